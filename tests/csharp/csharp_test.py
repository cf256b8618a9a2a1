"""The Unity-style C# package (client/csharp), proven under Mono: its Runtime
compiled with mcs (warnings as errors), the test program
(tests/csharp/CsharpClientTest.cs) and the package's example compiled against
it and run with mono against a gmr-server on loopback, loading
libgmr_client_c by P/Invoke as a Unity plugin would. For a CMU BVH (its unit
given by the subscription) and a CMU ASF/AMC take, each re-rooted: every polled
frame's positions equal `gmr positions` in Unity's conventions (Y up, Z
forward, left-handed, metres) to 1e-9 m, the local transforms compose to the
same positions, a root change while streaming arrives as a new skeleton, a
query of the view agrees, and refusals come back as GmrException with the
server's status. The Unity component (Runtime/Unity) is compiled against a stub
of the UnityEngine types it uses (a compile check; it is not run).

    csharp_test.py --repo . --bin-dir build/bin --lib-dir build/lib

Exits 77 (skipped) outside CI when mcs, mono, numpy or the corpus is missing;
under CI=true that is a failure.
"""

import argparse
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "python"))
import gmr_test_env as env  # noqa: E402

FRAMES = 40


def parse(path):
    """The test program's lines: skeletons, frames by phase, and the rest by kind."""
    skeletons, frames, other = [], [], {}
    for line in pathlib.Path(path).read_text().splitlines():
        kind, _, rest = line.partition(" ")
        if kind == "skeleton":
            version, *joints = rest.split(" ")
            skeletons.append((int(version), [(j.rsplit(":", 1)[0], int(j.rsplit(":", 1)[1])) for j in joints]))
        elif kind == "frame":
            phase, index, version, *values = rest.split(" ")
            frames.append((phase, int(index), int(version), [float(v) for v in values]))
        else:
            other.setdefault(kind, []).append(rest)
    return skeletons, frames, other


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", required=True)
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--lib-dir", required=True)
    args = ap.parse_args()
    repo = pathlib.Path(args.repo).resolve()
    mcs, mono = shutil.which("mcs"), shutil.which("mono")
    if mcs is None or mono is None:
        env.skip_or_fail("mcs or mono is not installed (scripts/install-deps.sh installs mono-mcs and mono-runtime)")
    np = env.require_numpy_and_corpus()
    bin_dir = pathlib.Path(args.bin_dir).resolve()
    work = pathlib.Path(tempfile.mkdtemp(prefix="gmr_csharp_"))
    package = repo / "client/csharp"

    def compile_cs(*cmd):
        r = subprocess.run([mcs, *cmd], capture_output=True, text=True, cwd=work)
        if r.returncode != 0:
            print(f"mcs {' '.join(cmd)} failed:\n{r.stdout}{r.stderr}", file=sys.stderr)
            sys.exit(1)

    runtime = sorted(str(p) for p in (package / "Runtime").glob("*.cs"))
    compile_cs("-target:library", "-out:Gmr.Runtime.dll", "-warnaserror", *runtime)
    compile_cs("-out:test.exe", "-r:Gmr.Runtime.dll", "-warnaserror", str(repo / "tests/csharp/CsharpClientTest.cs"))
    compile_cs("-out:example.exe", "-r:Gmr.Runtime.dll", "-warnaserror", str(package / "Samples~/Console/Example.cs"))
    compile_cs("-target:library", "-out:UnityComponent.dll", "-define:UNITY_5_3_OR_NEWER", "-warnaserror",
               str(repo / "tests/csharp/UnityEngineStub.cs"), *runtime, str(package / "Runtime/Unity/GmrLiveLink.cs"))

    lib = env.cmu_library(work / "library")
    # A character rig with Unity's humanoid names, a T-pose in centimetres: for
    # the C# program as lines, for `gmr retarget` as a BVH (the same joints:
    # its End Sites are the "_End" lines).
    rig = [("Hips", -1, 0, 100, 0), ("Spine", 0, 0, 10, 0), ("Head", 1, 0, 50, 0), ("Head_End", 2, 0, 15, 0),
           ("LeftUpperArm", 1, 20, 40, 0), ("LeftLowerArm", 4, 30, 0, 0), ("LeftHand", 5, 25, 0, 0),
           ("LeftHand_End", 6, 15, 0, 0), ("RightUpperArm", 1, -20, 40, 0), ("RightLowerArm", 8, -30, 0, 0),
           ("RightHand", 9, -25, 0, 0), ("RightHand_End", 10, -15, 0, 0), ("LeftUpperLeg", 0, 10, -5, 0),
           ("LeftLowerLeg", 12, 0, -45, 0), ("LeftFoot", 13, 0, -45, 0), ("LeftFoot_End", 14, 0, -5, 12),
           ("RightUpperLeg", 0, -10, -5, 0), ("RightLowerLeg", 16, 0, -45, 0), ("RightFoot", 17, 0, -45, 0),
           ("RightFoot_End", 18, 0, -5, 12)]
    (work / "rig.txt").write_text("".join(f"{n} {p} {x} {y} {z}\n" for n, p, x, y, z in rig))

    def bvh_joint(j, depth):
        n, p, x, y, z = rig[j]
        pad = "  " * depth
        if n.endswith("_End"):
            return f"{pad}End Site\n{pad}{{\n{pad}  OFFSET {x} {y} {z}\n{pad}}}\n"
        channels = ("6 Xposition Yposition Zposition" if p < 0 else "3") + " Zrotation Xrotation Yrotation"
        out = f"{pad}{'ROOT' if p < 0 else 'JOINT'} {n}\n{pad}{{\n{pad}  OFFSET {x} {y} {z}\n{pad}  CHANNELS {channels}\n"
        out += "".join(bvh_joint(k, depth + 1) for k in range(len(rig)) if rig[k][1] == j)
        return out + f"{pad}}}\n"
    values = 6 + 3 * sum(1 for n, p, *_ in rig if p >= 0 and not n.endswith("_End"))
    (work / "rig.bvh").write_text("HIERARCHY\n" + bvh_joint(0, 0) + "MOTION\nFrames: 1\nFrame Time: 0.0333333\n"
                                  + " ".join(["0"] * values) + "\n")
    run_env = dict(os.environ, LD_LIBRARY_PATH=str(pathlib.Path(args.lib_dir).resolve()))
    # (motion, file, roots, roots asked while streaming, unit given to the subscription, unit flag for gmr positions)
    cases = [("02_01", lib / "02_01.bvh", "LeftFoot", "Head", 0.0254, ["--metres-per-unit", "0.0254"]),
             ("07/07_05-walk", lib / "07/07_05-walk.amc", "lfoot", "head,rhand", 0.0, [])]
    failures = []
    checked = 0
    with env.Server(bin_dir, library=lib) as server:
        example = subprocess.run([mono, str(work / "example.exe"), "127.0.0.1", str(server.port), "02_01", "Head"],
                                 capture_output=True, text=True, env=run_env, timeout=60)
        shown = [line for line in example.stdout.splitlines() if line.startswith("frame ")]
        if example.returncode != 0 or len(shown) != 5 or "02_01: 38 joints" not in example.stdout:
            failures.append(f"the example failed ({example.returncode}):\n{example.stdout}{example.stderr}")
        for motion, path, roots, new_roots, mpu, unit in cases:
            out = work / (motion.replace("/", "_") + ".txt")
            run = subprocess.run([mono, str(work / "test.exe"), "--port", str(server.port), "--motion", motion, "--roots",
                                  roots, "--new-roots", new_roots, "--mpu", repr(mpu), "--frames", str(FRAMES), "--out",
                                  str(out), "--rig", str(work / "rig.txt") if motion == "02_01" else ""],
                                 capture_output=True, text=True, env=run_env, timeout=300)
            if run.returncode != 0:
                failures.append(f"{motion}: the C# test program failed ({run.returncode}):\n{run.stdout[-3000:]}"
                                f"{run.stderr[-3000:]}")
                continue
            skeletons, frames, other = parse(out)
            if other.get("unit") != ["1"]:
                failures.append(f"{motion}: the subscription says its unit is {other.get('unit')} m, not metres")
            if other.get("listed") != ["True"]:
                failures.append(f"{motion}: ListMotions did not name it")
            if len(skeletons) != 2 or skeletons[0][0] == skeletons[1][0]:
                failures.append(f"{motion}: {len(skeletons)} skeletons seen, versions {[s[0] for s in skeletons]}")
                continue
            for phase, (version, joints), roots_list in (("before", skeletons[0], roots),
                                                          ("after", skeletons[1], new_roots)):
                names = [n for n, _ in joints]
                parents = [p for _, p in joints]
                got_roots = sorted(n for n, p in joints if p < 0)
                if got_roots != sorted(roots_list.split(",")):
                    failures.append(f"{motion} {phase}: roots {got_roots}, not {roots_list}")
                want, want_names = env.gmr_positions(bin_dir, path, "--conventions", "unity", "--roots", roots_list,
                                                     *unit)
                order = [want_names.index(n) for n in names]
                mine = [f for f in frames if f[0] == phase]
                if len(mine) < FRAMES:
                    failures.append(f"{motion} {phase}: {len(mine)} frames")
                n = len(names)
                for _, index, frame_version, values in mine:
                    if frame_version != version or len(values) != 14 * n:
                        failures.append(f"{motion} {phase}: frame {index} of version {frame_version} with "
                                        f"{len(values)} values for {n} joints")
                        break
                    v = np.array(values)
                    positions = v[:3 * n].reshape(n, 3)
                    orientations = v[3 * n:7 * n].reshape(n, 4)
                    rotations = v[7 * n:11 * n].reshape(n, 4)
                    translations = v[11 * n:].reshape(n, 3)
                    err = float(np.abs(positions - want[index][order]).max())
                    composed = env.compose_locals(parents, rotations, translations)
                    err_locals = float(np.abs(composed - positions).max())
                    norm = float(np.abs(np.linalg.norm(orientations, axis=1) - 1).max())
                    checked += 1
                    if err > 1e-9 or err_locals > 1e-9 or norm > 1e-9:
                        failures.append(f"{motion} {phase}: frame {index}: positions {err:.3g} m from gmr positions, "
                                        f"local transforms compose to {err_locals:.3g} m from them, "
                                        f"orientation norms off by {norm:.3g}")
                        break
            # The query: the view as it ended (new roots), first 3 frames, Unity's axes in the file's units
            # (the C ABI's query takes no source unit).
            count, *q = other["query"][0].split(" ")
            want, want_names = env.gmr_positions(bin_dir, path, "--conventions", "unity", "--roots", new_roots,
                                                 *([] if mpu else unit))
            names = [n for n, _ in skeletons[1][1]]
            order = [want_names.index(name) for name in names]
            got = np.array([float(x) for x in q]).reshape(3, int(count), 3)
            if float(np.abs(got - want[:3][:, order]).max()) > 1e-9:
                failures.append(f"{motion}: the query is {float(np.abs(got - want[:3][:, order]).max()):.3g} off")
            errors = other.get("error", [])
            statuses = [e.split(" ")[0] for e in errors]
            if motion == "02_01":
                # On the rig: its first frames as `gmr retarget` onto the same rig puts them, in metres.
                on_rig = work / "02_01_on_rig.bvh"
                subprocess.run([str(bin_dir / "gmr"), "retarget", str(path), str(on_rig), "--target",
                                str(work / "rig.bvh")], check=True, capture_output=True)
                want, want_names = env.gmr_positions(bin_dir, on_rig, "--conventions", "unity", "--metres-per-unit",
                                                     "0.01")
                count, *r = other["retarget"][0].split(" ")
                got = np.array([float(x) for x in r]).reshape(3, int(count), 3)
                order = [want_names.index(name) for name, *_ in rig]
                err = float(np.abs(got - want[:3][:, order]).max()) if int(count) == len(rig) else float("inf")
                checked += 1
                if err > 1e-9:
                    failures.append(f"{motion}: retargeted by C# onto the rig: {count} joints, {err:.3g} m from "
                                    "gmr retarget's")
                if statuses[:1] != ["FailedPrecondition"] or "'LeftPaw'" not in errors[0]:
                    failures.append(f"{motion}: a map naming an absent joint came back as {errors[:1]}")
                statuses = statuses[1:]
            if statuses != ["NotFound", "NotFound", "BadRequest"]:
                failures.append(f"{motion}: refusals came back as {other.get('error')}")
            received, replaced = (int(x) for x in other["counts"][0].split(" "))
            print(f"{motion} (roots {roots}, then {new_roots}): {FRAMES} + {FRAMES} frames polled; received {received}, "
                  f"replaced {replaced}; latency {float(other['latency'][0]):.2f} ms")
    env.finish(failures, checked, len(cases) * 2 * FRAMES)
    print(f"C# package under Mono: {len(cases)} motions, {checked} frames equal gmr positions in Unity's conventions; "
          f"the example ran; the Unity component compiled against a stub")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
