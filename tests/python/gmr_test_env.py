"""What the Python-side tests share: where the build and the corpus are, how
a test that cannot run says so (exit 77 outside CI, a failure under CI=true),
a gmr-server started on loopback for the test, and `gmr positions` as numpy."""

import csv
import io
import os
import pathlib
import subprocess
import sys
import tempfile
import time

SKIP = 77
IN_CI = os.environ.get("CI") == "true"
REPO = pathlib.Path(__file__).resolve().parents[2]


def skip_or_fail(reason: str):
    """Outside CI: skip the whole test program (exit 77). Under CI=true: fail."""
    if IN_CI:
        print(f"FAIL (CI=true): {reason}", file=sys.stderr)
        sys.exit(1)
    print(f"SKIP: {reason}", file=sys.stderr)
    sys.exit(SKIP)


def data_dir() -> pathlib.Path:
    return pathlib.Path(os.environ.get("GMR_DATA_DIR", REPO.parent / "shared" / "data"))


def have_data() -> bool:
    return data_dir().is_dir()


def require_numpy_and_corpus():
    """numpy (returned) and the corpus, or skip (outside CI) / fail without them."""
    try:
        import numpy
    except ImportError:
        skip_or_fail("numpy is missing (scripts/install-deps.sh installs python3-numpy)")
    if not have_data():
        skip_or_fail(f"the corpus is missing at {data_dir()}")
    return numpy


def cmu_library(root: pathlib.Path) -> pathlib.Path:
    """A library folder of links into the corpus: CMU 02_01 as BVH (02_01)
    and CMU 07_05 as ASF/AMC (07/07_05-walk)."""
    d = data_dir()
    (root / "07").mkdir(parents=True, exist_ok=True)
    for src, dst in (("bvh/cmu/02_01.bvh", "02_01.bvh"), ("asfamc/07/07-walk.asf", "07/07-walk.asf"),
                     ("asfamc/07/07_05-walk.amc", "07/07_05-walk.amc")):
        if not (root / dst).exists():
            os.symlink(d / src, root / dst)
    return root


def finish(failures, checked: int, at_least: int) -> None:
    """Ends a test program: exit 1 with every failure, or when fewer than
    `at_least` frames were checked (a test that compared nothing passes nothing)."""
    if failures:
        print("\n".join(failures), file=sys.stderr)
        sys.exit(1)
    if checked < at_least:
        print(f"only {checked} frames checked, at least {at_least} expected", file=sys.stderr)
        sys.exit(1)


class Server:
    """gmr-server on 127.0.0.1 with any free port, stopped on exit. `http`: False
    (no HTTP port), True (any free one) or a port number (a server started
    again where an earlier one listened)."""

    def __init__(self, bin_dir, *args, library=None, http=False):
        self.bin_dir = pathlib.Path(bin_dir)
        self._tmp = tempfile.TemporaryDirectory(prefix="gmr_py_")
        port_file = pathlib.Path(self._tmp.name) / "port"
        http_port_file = pathlib.Path(self._tmp.name) / "http_port"
        cmd = [str(self.bin_dir / "gmr-server"), "--port", "0", "--port-file", str(port_file), "--log-level", "warn"]
        # HTTP (the viewer, /metrics) on any free port, or none.
        http_port = 0 if http is True else int(http)
        cmd += ["--http-port", str(http_port), "--http-port-file", str(http_port_file)] if http else ["--http-port", "-1"]
        if library is not None:
            cmd += ["--library", str(library)]
        cmd += list(args)
        self.process = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        files = [port_file, http_port_file] if http else [port_file]
        while not all(f.exists() and f.read_text().strip() for f in files):
            if self.process.poll() is not None:
                raise RuntimeError(f"gmr-server exited with {self.process.returncode}: {self.process.stderr.read()}")
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError("gmr-server did not start listening within 60 s")
            time.sleep(0.02)
        self.port = int(port_file.read_text())
        self.http_port = int(http_port_file.read_text()) if http else None

    def stop(self):
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stderr:
            self.process.stderr.close()
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


def gmr_positions(bin_dir, path, *args):
    """`gmr positions PATH ARGS` as (frames, joints, 3) float64 and the joint names."""
    import numpy as np
    out = subprocess.run([str(pathlib.Path(bin_dir) / "gmr"), "positions", str(path), *args], check=True,
                         capture_output=True, text=True).stdout
    rows = list(csv.reader(io.StringIO(out)))
    assert rows[0][:5] == ["frame", "joint", "x", "y", "z"], rows[0]
    names = []
    values = []
    for r in rows[1:]:
        if r[0] == rows[1][0]:
            names.append(r[1])
        values.append([float(r[2]), float(r[3]), float(r[4])])
    a = np.array(values, dtype=np.float64)
    return a.reshape(-1, len(names), 3), names


def compose_locals(parents, rotations, translations):
    """World positions from engine-bone locals (O_j = O_p Q_j, P_j = P_p + O_p T_j); quaternions x, y, z, w."""
    import numpy as np

    def matrix(q):
        x, y, z, w = q
        return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])

    n = len(parents)
    frames = [None] * n
    positions = np.zeros((n, 3))
    for j in range(n):
        r = matrix(rotations[j])
        p = parents[j]
        if p < 0:
            frames[j] = r
            positions[j] = translations[j]
        else:
            frames[j] = frames[p] @ r
            positions[j] = positions[p] + frames[p] @ translations[j]
    return positions


def http_get(port, path, method="GET"):
    """(status, content type, body) of an HTTP request to a server on 127.0.0.1."""
    import urllib.error
    import urllib.request
    request = urllib.request.Request(f"http://127.0.0.1:{port}{path}", method=method)
    try:
        with urllib.request.urlopen(request, timeout=10) as r:
            return r.status, r.headers.get("Content-Type"), r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.headers.get("Content-Type"), e.read().decode()


def scrape_metrics(port):
    """/metrics through the Prometheus client library's own parser: ({(name, ((label, value), ...)): value},
    {family: type})."""
    from prometheus_client.parser import text_string_to_metric_families
    status, content_type, text = http_get(port, "/metrics")
    assert status == 200, (status, text)
    assert content_type.startswith("text/plain; version=0.0.4"), content_type
    samples, types = {}, {}
    for family in text_string_to_metric_families(text):
        types[family.name] = family.type
        for s in family.samples:
            samples[(s.name, tuple(sorted(s.labels.items())))] = s.value
    return samples, types
