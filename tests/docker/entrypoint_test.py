#!/usr/bin/env python3
"""docker/entrypoint.sh: the flags it gives gmr-server (with a stub that
prints them), then the real gmr-server started through it with a mounted
auth file, reached by the real gmr command.

    entrypoint_test.py REPO_DIR BIN_DIR
"""
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time


def run_entrypoint(entrypoint, path_dir, env_extra, args):
    env = dict(os.environ)
    env["PATH"] = path_dir + os.pathsep + env["PATH"]
    env.update(env_extra)
    out = subprocess.run(["sh", entrypoint, *args], env=env, capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    return out.stdout.split("\x1f")[:-1]


def check_flags(entrypoint, work):
    stub_dir = os.path.join(work, "stub")
    os.makedirs(stub_dir)
    stub = os.path.join(stub_dir, "gmr-server")
    with open(stub, "w") as f:
        f.write('#!/bin/sh\nfor a in "$@"; do printf "%s\\037" "$a"; done\n')
    os.chmod(stub, 0o755)
    library = os.path.join(work, "library")
    secrets = os.path.join(work, "secrets with space")
    os.makedirs(library)
    os.makedirs(secrets)
    env = {"GMR_LIBRARY_DIR": library, "GMR_SECRETS_DIR": secrets}

    # Nothing mounted: every interface inside the container, the demo library.
    got = run_entrypoint(entrypoint, stub_dir, env, ["--port", "7400"])
    assert got == ["--bind", "0.0.0.0", "--port", "7400"], got

    # A library, an auth file and a TLS pair mounted; GMR_BIND chosen.
    open(os.path.join(library, "a.bvh"), "w").close()
    for name in ("gmr-auth", "gmr-tls-cert", "gmr-tls-key"):
        open(os.path.join(secrets, name), "w").close()
    got = run_entrypoint(entrypoint, stub_dir, {**env, "GMR_BIND": "10.1.2.3"}, ["--log-level", "debug"])
    assert got == ["--bind", "10.1.2.3", "--library", library,
                   "--auth-file", os.path.join(secrets, "gmr-auth"),
                   "--tls-cert", os.path.join(secrets, "gmr-tls-cert"),
                   "--tls-key", os.path.join(secrets, "gmr-tls-key"),
                   "--log-level", "debug"], got

    # Flags given by the operator replace the entrypoint's.
    got = run_entrypoint(entrypoint, stub_dir, env, ["--bind=127.0.0.1", "--auth-file", "/etc/gmr/auth",
                                                    "--library", "/data", "--tls-cert", "c", "--tls-key", "k"])
    assert got == ["--bind=127.0.0.1", "--auth-file", "/etc/gmr/auth", "--library", "/data",
                   "--tls-cert", "c", "--tls-key", "k"], got

    # A certificate without its key is not half-used.
    os.remove(os.path.join(secrets, "gmr-tls-key"))
    got = run_entrypoint(entrypoint, stub_dir, env, [])
    assert "--tls-cert" not in got, got
    print("entrypoint flags: 4 cases")


def check_real_server(entrypoint, bin_dir, work):
    secrets = os.path.join(work, "real-secrets")
    os.makedirs(secrets)
    auth = os.path.join(secrets, "gmr-auth")
    with open(auth, "w") as f:
        f.write("control 0123456789abcdef0123456789abcdef\n")
    os.chmod(auth, 0o600)
    port_file = os.path.join(work, "port")
    env = dict(os.environ)
    env.update({"PATH": bin_dir + os.pathsep + env["PATH"], "GMR_SECRETS_DIR": secrets,
                "GMR_LIBRARY_DIR": os.path.join(work, "empty"), "GMR_BIND": "127.0.0.1"})
    server = subprocess.Popen(["sh", entrypoint, "--port", "0", "--port-file", port_file, "--anonymous", "none"],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.time() + 20
        while not os.path.exists(port_file):
            assert server.poll() is None, server.stdout.read()
            assert time.time() < deadline, "gmr-server did not start"
            time.sleep(0.05)
        port = open(port_file).read().strip()
        gmr = os.path.join(bin_dir, "gmr")
        ok = subprocess.run([gmr, "ls", "--port", port, "--token", "0123456789abcdef0123456789abcdef"],
                            capture_output=True, text=True, timeout=30)
        assert ok.returncode == 0 and "walk" in ok.stdout, ok.stdout + ok.stderr
        refused = subprocess.run([gmr, "ls", "--port", port], capture_output=True, text=True, timeout=30)
        assert refused.returncode == 1 and "UNAUTHENTICATED" in refused.stderr, refused.stdout + refused.stderr
        # A new token, read again on SIGHUP: the old one stops working, the new one works.
        with open(auth, "w") as f:
            f.write("control fedcba9876543210fedcba9876543210\n")
        server.send_signal(signal.SIGHUP)
        deadline = time.time() + 20
        while True:
            new = subprocess.run([gmr, "ls", "--port", port, "--token", "fedcba9876543210fedcba9876543210"],
                                 capture_output=True, text=True, timeout=30)
            if new.returncode == 0:
                break
            assert time.time() < deadline, new.stderr
            time.sleep(0.1)
        old = subprocess.run([gmr, "ls", "--port", port, "--token", "0123456789abcdef0123456789abcdef"],
                             capture_output=True, text=True, timeout=30)
        assert old.returncode == 1 and "UNAUTHENTICATED" in old.stderr, old.stdout + old.stderr
    finally:
        server.terminate()
        log = server.communicate(timeout=20)[0]
    assert server.returncode == 0, log
    assert "1 tokens, anonymous clients none" in log, log
    assert "SIGHUP: 1 tokens read from" in log, log
    print("real gmr-server through the entrypoint: token accepted, anonymous refused, tokens rotated on SIGHUP")


def main():
    repo, bin_dir = sys.argv[1], sys.argv[2]
    entrypoint = os.path.join(repo, "docker", "entrypoint.sh")
    work = tempfile.mkdtemp(prefix="gmr-entrypoint-")
    try:
        check_flags(entrypoint, work)
        check_real_server(entrypoint, bin_dir, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
