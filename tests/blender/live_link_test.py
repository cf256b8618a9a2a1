"""The Blender live link, proven in Blender: for the built-in demo, a CMU BVH
and a CMU ASF/AMC take, a gmr-server started here streams to the add-on
(client/blender/gmr_live_link) running in headless Blender, which builds the
armature from the subscription's skeleton and rest pose and poses it from
each frame's local transforms in Blender's conventions. Every applied frame's
pose-bone heads (world space) must equal `gmr positions` of that frame with
the same roots and viewpoint, converted to Blender's axes and metres, to
1e-4 of the skeleton's size: before and after a root change requested from
Blender (the armature is rebuilt with the new hierarchy), and when the
Action the add-on recorded is played back. And the user's own character: a
Mixamo rig imported by Blender's BVH importer, selected, is the armature the
add-on asks the server to retarget CMU 02_01 onto; its bone heads must equal
`gmr retarget` onto the same BVH (same tolerance), and each bone's rotation
must turn its rest direction onto its child (what skinning sees).

    live_link_test.py --repo . --bin-dir build/bin --python-dir build/python

Exits 77 (skipped) outside CI when Blender, numpy, python3-protobuf or the
corpus is missing; under CI=true that is a failure.
"""

import argparse
import json
import pathlib
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "python"))
import gmr_test_env as env  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", required=True)
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--python-dir", required=True)
    ap.add_argument("--keep", help="keep the Blender outputs in this folder")
    args = ap.parse_args()
    repo = pathlib.Path(args.repo).resolve()
    blender = shutil.which("blender")
    if blender is None:
        env.skip_or_fail("blender is not installed (scripts/install-deps.sh installs it)")
    np = env.require_numpy_and_corpus()

    work = pathlib.Path(args.keep) if args.keep else pathlib.Path(tempfile.mkdtemp(prefix="gmr_blender_"))
    work.mkdir(parents=True, exist_ok=True)
    bin_dir = pathlib.Path(args.bin_dir).resolve()
    subprocess.run([str(bin_dir / "gmr"), "demo", str(work / "demo"), "--format", "gmr"], check=True,
                   capture_output=True)
    lib = env.cmu_library(work / "library")

    # (server library or None for the built-in demo, motion, file for gmr
    # positions, its unit flag, roots, viewpoint, roots asked from Blender)
    cases = [
        (None, "walk", work / "demo/walk.gmr", ["--metres-per-unit", "0.01"], "head", "", "l_toe,r_hand"),
        (None, "wave", work / "demo/wave.gmr", ["--metres-per-unit", "0.01"], "", "pelvis", "l_hand"),
        (lib, "02_01", lib / "02_01.bvh", ["--metres-per-unit", "0.0254"], "", "", "Head"),
        (lib, "07/07_05-walk", lib / "07/07_05-walk.amc", [], "lfoot", "", "head,rhand"),
    ]
    failures = []
    checked = 0
    for library, motion, path, unit, roots, viewpoint, new_roots in cases:
        label = f"{motion} (roots '{roots}', viewpoint '{viewpoint}', then roots '{new_roots}')"
        server_args = [] if library is None else ["--metres-per-unit", "0.0254"]
        with env.Server(bin_dir, *server_args, library=library) as server:
            out = work / (motion.replace("/", "_") + ".json")
            run = subprocess.run([blender, "-b", "--factory-startup", "--python",
                                  str(repo / "tests/blender/live_link_in_blender.py"), "--",
                                  "--addon-dir", str(repo / "client/blender"), "--python-dir",
                                  str(pathlib.Path(args.python_dir).resolve()), "--port", str(server.port),
                                  "--motion", motion, "--roots", roots, "--viewpoint", viewpoint,
                                  "--new-roots", new_roots, "--out", str(out)],
                                 capture_output=True, text=True, timeout=300)
            if run.returncode != 0 or not out.exists():
                failures.append(f"{label}: Blender failed ({run.returncode}):\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
                continue
        result = json.loads(out.read_text())

        def expected(roots_list):
            flags = ["--conventions", "blender", *unit]
            if roots_list:
                flags += ["--roots", roots_list]
            if viewpoint:
                flags += ["--relative-to", viewpoint]
            return env.gmr_positions(bin_dir, path, *flags)

        for phase, roots_list in (("before", roots), ("after", new_roots)):
            want, names = expected(roots_list)
            size = max(float(np.linalg.norm(want[0] - want[0][k])) for k in range(len(names)))
            samples = result[phase]
            if len(samples) < 20:
                failures.append(f"{label}: only {len(samples)} frames applied {phase} the root change")
            for s in samples:
                heads = s["heads"]
                if sorted(heads) != sorted(names):
                    failures.append(f"{label} {phase}: bones {sorted(heads)[:5]}... are not the joints {sorted(names)[:5]}...")
                    break
                got = np.array([heads[n] for n in names])
                err = float(np.abs(got - want[s["frame"]]).max())
                checked += 1
                if err > 1e-4 * size:
                    worst = names[int(np.abs(got - want[s["frame"]]).max(axis=1).argmax())]
                    failures.append(f"{label} {phase}: frame {s['frame']}: a head is {err:.3g} m off "
                                    f"(bone {worst}; allowed {1e-4 * size:.3g})")
                    break
        want_roots = sorted(r.strip() for r in new_roots.split(","))
        if sorted(result["roots_after"]) != want_roots:
            failures.append(f"{label}: the armature's roots after the change are {result['roots_after']}, not {want_roots}")
        if result["versions"][0] == result["versions"][1]:
            failures.append(f"{label}: the skeleton version did not change")
        # The recorded Action plays back the same heads.
        want, names = expected(new_roots)
        size = max(float(np.linalg.norm(want[0] - want[0][k])) for k in range(len(names)))
        if result["action_fcurves"] != 7 * result["bones"] or not result["played"]:
            failures.append(f"{label}: the Action has {result['action_fcurves']} F-curves for {result['bones']} bones "
                            f"and played {len(result['played'])} frames")
        for s in result["played"]:
            got = np.array([s["heads"][n] for n in names])
            err = float(np.abs(got - want[s["frame"]]).max())
            checked += 1
            if err > 1e-4 * size:
                failures.append(f"{label}: the recorded Action at frame {s['frame']} is {err:.3g} m off")
                break
        print(f"{label}: {len(result['before'])} + {len(result['after'])} frames applied, "
              f"{len(result['played'])} played from the Action")

    # The selected armature as the target.
    rig = env.data_dir() / "bvh/mixamo/Beta_jump.bvh"
    retargeted = work / "02_01_on_beta.bvh"
    subprocess.run([str(bin_dir / "gmr"), "retarget", str(lib / "02_01.bvh"), str(retargeted), "--target", str(rig)],
                   check=True, capture_output=True)
    want, names = env.gmr_positions(bin_dir, retargeted, "--conventions", "blender")
    size = max(float(np.linalg.norm(want[0] - want[0][k])) for k in range(len(names)))
    with env.Server(bin_dir, "--metres-per-unit", "0.0254", library=lib) as server:
        out = work / "retarget.json"
        run = subprocess.run([blender, "-b", "--factory-startup", "--python",
                              str(repo / "tests/blender/live_link_in_blender.py"), "--",
                              "--addon-dir", str(repo / "client/blender"), "--python-dir",
                              str(pathlib.Path(args.python_dir).resolve()), "--port", str(server.port),
                              "--motion", "02_01", "--new-roots", "", "--target-bvh", str(rig), "--out", str(out)],
                             capture_output=True, text=True, timeout=300)
    if run.returncode != 0 or not out.exists():
        failures.append(f"retarget onto the selected armature: Blender failed ({run.returncode}):\n"
                        f"{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
    else:
        result = json.loads(out.read_text())
        index = {n: k for k, n in enumerate(names)}
        bones = sorted(result["before"][0]["heads"]) if result["before"] else []
        if len(bones) != result["bones"] or any(b not in index for b in bones):
            failures.append(f"retarget: the armature's {result['bones']} bones are not all joints of gmr retarget's output")
        worst = 0.0
        for s in result["before"]:
            got = np.array([s["heads"][b] for b in bones])
            err = float(np.abs(got - want[s["frame"]][[index[b] for b in bones]]).max())
            worst = max(worst, err)
            checked += 1
            if err > 1e-4 * size:
                failures.append(f"retarget: frame {s['frame']}: a head of '{result['object']}' is {err:.3g} off "
                                f"gmr retarget's (allowed {1e-4 * size:.3g})")
                break
        if not result["character_kept"] or result["built"] == result["object"]:
            failures.append(f"retarget: streaming without a target afterwards touched the user's armature "
                            f"(kept: {result['character_kept']}, built '{result['built']}')")
        misses = result["rotation_misses"]
        bad = {b: m for b, m in misses.items() if m > 1e-4}
        if len(misses) < 20 or bad:
            failures.append(f"retarget: {len(misses)} bones checked; rotations that miss their child: {bad}")
        print(f"retarget onto the selected armature ({result['object']}, {result['bones']} bones): "
              f"{len(result['before'])} frames, largest head difference {worst:.3g} (size {size:.3g}), "
              f"largest rotation miss {max(misses.values(), default=0):.2g}")

    env.finish(failures, checked, 4 * 40 + 20)
    print(f"live link in Blender: {len(cases)} motions, {checked} frames checked")
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
