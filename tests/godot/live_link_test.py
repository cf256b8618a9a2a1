"""The Godot add-on (client/godot/addons/gmr_live_link), proven in a real
Godot: headless Godot 3 (godot3-server) runs tests/godot/live_link_in_godot.gd
with a Skeleton and the add-on's GmrLiveLink against a gmr-server started
here on loopback. For the built-in demo, a CMU BVH (its unit given by the
link's source_metres_per_unit) and a CMU ASF/AMC take, each re-rooted or seen
from a joint: every applied frame's Skeleton bone global positions must equal
`gmr positions` of that frame with the same roots and viewpoint in Godot's
conventions and metres, within 1e-4 m; before and after a root change asked
mid-stream from Godot (the bones rebuilt with the new hierarchy), and, for the
BVH, after the server was stopped and started again (the link reconnects and
builds the same view again). And a user's character: a Skeleton with the
Mixamo rig's bones (names as Godot has them, `mixamorig_Hips`; each bone's
rest turned its own way) and the link's retarget_onto_skeleton: the bones keep
their names and parents, their global positions equal `gmr retarget` of the
motion onto that rig within 2e-5 of its height, and each bone's rest axis
(pointing at its child at rest) points at its child in every frame; a
Skeleton that is no humanoid ends the link with the missing roles named.

    live_link_test.py --repo . --bin-dir build/bin --python-dir client/python

Exits 77 (skipped) outside CI when godot3-server, numpy or the corpus is
missing; under CI=true that is a failure.
"""

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "python"))
import gmr_test_env as env  # noqa: E402

FRAMES = 30        # frames compared per phase
TOLERANCE = 1e-4   # metres


def run_godot(godot, project, out, server_port, case, restart_with):
    """Runs the driver; when it asks (OUT.restart), stops the server and starts
    another on the same HTTP port with `restart_with()`. Returns (result, log)."""
    motion, roots, viewpoint, mpu, new_roots = case
    run_env = dict(godot_env(project), GMR_PORT=str(server_port), GMR_MOTION=motion, GMR_ROOTS=roots, GMR_RELATIVE_TO=viewpoint,
                   GMR_MPU=str(mpu), GMR_NEW_ROOTS=new_roots, GMR_FRAMES=str(FRAMES), GMR_OUT=str(out),
                   GMR_RESTART="1" if restart_with else "0")
    log = out.with_suffix(".log")
    with open(log, "w") as log_file:
        godot_process = subprocess.Popen([godot, "--path", str(project), "-s", "res://test_driver.gd"],
                                         stdout=log_file, stderr=subprocess.STDOUT, env=run_env)
        restarted = None
        deadline = time.monotonic() + 240
        try:
            while godot_process.poll() is None:
                if time.monotonic() > deadline:
                    godot_process.kill()
                    break
                marker = pathlib.Path(str(out) + ".restart")
                if restart_with and restarted is None and marker.exists():
                    restarted = restart_with()
                time.sleep(0.05)
            godot_process.wait()
        finally:
            if restarted is not None:
                restarted.stop()
    text = log.read_text(errors="replace")
    if not out.exists():
        return None, text
    return json.loads(out.read_text()), text


def godot_env(project):
    return dict(os.environ, HOME=str(project.parent), XDG_DATA_HOME=str(project.parent / "data"),
                XDG_CONFIG_HOME=str(project.parent / "config"), LANG="en_US.UTF-8")


def hostile_messages(godot, project, work):
    """What a broken or hostile server could send, handed to the add-on without
    a socket (tests/godot/hostile_messages.gd): each refused and counted, the
    Skeleton still usable, and a good skeleton and frame after them applied."""
    out = work / "hostile.json"
    run = subprocess.run([godot, "--path", str(project), "-s", "res://hostile_messages.gd"], capture_output=True,
                         text=True, timeout=120, env=dict(godot_env(project), GMR_OUT=str(out)))
    if run.returncode != 0 or not out.exists() or "SCRIPT ERROR" in run.stdout + run.stderr:
        return [f"hostile messages: Godot failed ({run.returncode}):\n{run.stdout[-3000:]}{run.stderr[-3000:]}"]
    results = {r["case"]: r for r in json.loads(out.read_text())}
    failures = []
    refused_by_count = ["not JSON", "a frame that is a number", "a reply nobody asked for",
                        "a frame with too few values", "a frame with a NaN rotation", "a frame with a zero rotation"]
    refused_by_failing = ["a skeleton whose joint is its own parent", "two joints of one name",
                          "a frame slot past the joints"]
    for name in refused_by_count:
        if results[name]["bad"] != 1:
            failures.append(f"hostile messages: '{name}' counted {results[name]['bad']} bad messages, not 1")
    for name in refused_by_failing:
        if not results[name]["error"] or results[name]["bones"]:
            failures.append(f"hostile messages: '{name}' was not refused: {results[name]}")
    if results["a frame of another skeleton version"]["dropped"] != 1:
        failures.append("hostile messages: a frame of another skeleton version was not dropped")
    good = results["a good frame"]
    bones = {b[0]: b[1:] for b in good["bones"]}
    if good["frame_index"] != 12 or sorted(bones) != ["hips", "mixamorig_Spine"] or \
            max(abs(a - b) for a, b in zip(bones["hips"] + bones["mixamorig_Spine"], [1, 2, 3, 1, 2.5, 3])) > 1e-6:
        failures.append(f"hostile messages: the good frame after them was not applied as sent: {good}")
    if not failures:
        print(f"hostile messages: {len(results)} cases, {len(refused_by_count) + len(refused_by_failing) + 1} refused, "
              f"the good skeleton and frame after them applied")
    return failures


def character_bones(np, sk):
    """The rig `sk` (a gmr_client.Skeleton, rest pose = every rotation zero)
    as a Godot character's bones: names as Godot has them (':' -> '_'),
    parents, and each bone's rest in the Skeleton's space: at the joint, its
    Y axis at its first child (the parent's axes for a leaf), turned about it
    by 0.3 rad per bone, so no two bones share a rest orientation."""
    n = len(sk.names)
    parents = [int(p) for p in sk.parents]
    origin = np.zeros((n, 3))
    for j in range(n):
        origin[j] = (origin[parents[j]] if parents[j] >= 0 else 0) + sk.offsets[j]
    first_child = [-1] * n
    for j in range(n - 1, -1, -1):
        if parents[j] >= 0 and np.linalg.norm(sk.offsets[j]) > 1e-9:
            first_child[parents[j]] = j
    bases = [None] * n
    bones = []
    for j in range(n):
        if first_child[j] >= 0:
            y = sk.offsets[first_child[j]] / np.linalg.norm(sk.offsets[first_child[j]])
            ref = np.array([0.0, 0.0, 1.0]) if abs(y[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
            x = np.cross(y, ref)
            x /= np.linalg.norm(x)
            z = np.cross(x, y)
            a = 0.3 * j
            x, z = np.cos(a) * x - np.sin(a) * z, np.sin(a) * x + np.cos(a) * z
            bases[j] = np.column_stack([x, y, z])
        else:
            bases[j] = bases[parents[j]] if parents[j] >= 0 else np.eye(3)
        b = bases[j]
        bones.append({"name": godot_name(sk.names[j]), "parent": parents[j],
                      "rest": [*b[:, 0], *b[:, 1], *b[:, 2], *origin[j]]})
    return bones, first_child


def godot_name(joint):
    return joint.replace(":", "_").replace("/", "_")


def retarget_onto_character(godot, project, work, bin_dir, lib, np):
    """The motion 02_01 streamed onto a Godot character with the Mixamo rig's
    bones (tests/godot/retarget_in_godot.gd), and a Skeleton no humanoid
    naming fits refused. Returns (failures, frames checked)."""
    import gmr_client
    rig_file = env.data_dir() / "bvh/mixamo/Beta_jump.bvh"
    (lib / "rigs").mkdir(exist_ok=True)
    if not (lib / "rigs/Beta_jump.bvh").exists():
        os.symlink(rig_file, lib / "rigs/Beta_jump.bvh")
    on_rig = work / "02_01_on_mixamo.bvh"
    subprocess.run([str(bin_dir / "gmr"), "retarget", str(lib / "02_01.bvh"), str(on_rig), "--target", str(rig_file)],
                   check=True, capture_output=True)
    want, names = env.gmr_positions(bin_dir, on_rig)
    height = float(np.ptp(want[0][:, 1]))
    tolerance = 2e-5 * height
    failures = []
    checked = 0
    with env.Server(bin_dir, library=lib, http=True) as server:
        with gmr_client.Client("127.0.0.1", server.port) as c:
            sk = c.skeleton("rigs/Beta_jump")
        bones, first_child = character_bones(np, sk)
        # Hips, spine and head only (Unity's and Godot's names): close to a
        # humanoid, so the refusal names the roles it lacks.
        chain = [{"name": n, "parent": i - 1, "rest": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 10.0 * i, 0]}
                 for i, n in enumerate(["Hips", "Spine", "Head"])]
        results = {}
        for label, character in (("Mixamo character", bones), ("a three-bone chain", chain)):
            bones_file = work / (label.replace(" ", "_") + ".bones.json")
            bones_file.write_text(json.dumps(character))
            out = work / (label.replace(" ", "_") + ".json")
            out.unlink(missing_ok=True)
            run_env = dict(godot_env(project), GMR_PORT=str(server.http_port), GMR_MOTION="02_01",
                           GMR_FRAMES=str(FRAMES), GMR_OUT=str(out), GMR_BONES=str(bones_file))
            run = subprocess.run([godot, "--path", str(project), "-s", "res://retarget_driver.gd"], capture_output=True,
                                 text=True, timeout=240, env=run_env)
            log = run.stdout + run.stderr
            if not out.exists() or "SCRIPT ERROR" in log:
                failures.append(f"retarget in Godot, {label}: Godot failed ({run.returncode}):\n{log[-3000:]}")
                continue
            results[label] = json.loads(out.read_text())
    refused = results.get("a three-bone chain")
    if refused is not None and ("the server cannot retarget" not in refused["error"]
                                or "left_upper_arm" not in refused["error"] or refused["samples"]):
        failures.append(f"retarget in Godot: a three-bone chain was not refused naming its missing roles: "
                        f"{refused['error']!r}, {len(refused['samples'])} frames applied")
    result = results.get("Mixamo character")
    if result is None:
        return failures, checked
    if result["error"]:
        return failures + [f"retarget in Godot: {result['error']}"], checked
    if [b[0] for b in result["bones"]] != [b["name"] for b in bones] or \
            [b[1] for b in result["bones"]] != [b["parent"] for b in bones]:
        failures.append("retarget in Godot: the character's bones changed (names or parents)")
    if len(result["samples"]) < FRAMES or result["bad_messages"] != 0:
        failures.append(f"retarget in Godot: {len(result['samples'])} frames applied, "
                        f"{result['bad_messages']} bad messages")
    index = {godot_name(n): k for k, n in enumerate(names)}
    missing = [b["name"] for b in bones if b["name"] not in index]
    if missing:
        return failures + [f"retarget in Godot: gmr retarget's output has no joints {missing[:5]}"], checked
    worst = worst_angle = 0.0
    for sample in result["samples"]:
        poses = {name: np.array([float(v) for v in row]).reshape(4, 3) for name, row in sample["poses"].items()}
        ref = want[sample["frame"]]
        for j, b in enumerate(bones):
            err = float(np.linalg.norm(poses[b["name"]][3] - ref[index[b["name"]]]))
            worst = max(worst, err)
            c = first_child[j]
            if c >= 0:
                bone = poses[bones[c]["name"]][3] - poses[b["name"]][3]
                axis = poses[b["name"]][1]
                cos = float(np.dot(bone, axis) / (np.linalg.norm(bone) * np.linalg.norm(axis)))
                worst_angle = max(worst_angle, float(np.degrees(np.arccos(min(1.0, max(-1.0, cos))))))
        checked += 1
    if worst > tolerance:
        failures.append(f"retarget in Godot: a bone is {worst:.3g} off gmr retarget (allowed {tolerance:.3g}, "
                        f"2e-5 of the rig's height)")
    if worst_angle > 0.01:
        failures.append(f"retarget in Godot: a bone's rest axis is {worst_angle:.3g} deg off its child")
    print(f"retarget in Godot: {checked} frames of 02_01 on a Mixamo character ({len(bones)} bones, its own rests): "
          f"largest difference from gmr retarget {worst:.2g} (rig units, height {height:.4g}), bone axes within "
          f"{worst_angle:.2g} deg of their children; a three-bone chain refused: {refused and refused['error']!r}")
    return failures, checked


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", required=True)
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--python-dir", required=True, help="the Python client (client/python)")
    ap.add_argument("--keep", help="keep the Godot project and outputs in this folder")
    args = ap.parse_args()
    sys.path.insert(0, str(pathlib.Path(args.python_dir).resolve()))
    repo = pathlib.Path(args.repo).resolve()
    godot = shutil.which("godot3-server")
    if godot is None:
        env.skip_or_fail("godot3-server is not installed (scripts/install-deps.sh installs it)")
    np = env.require_numpy_and_corpus()

    work = pathlib.Path(args.keep) if args.keep else pathlib.Path(tempfile.mkdtemp(prefix="gmr_godot_"))
    work.mkdir(parents=True, exist_ok=True)
    bin_dir = pathlib.Path(args.bin_dir).resolve()
    # The add-on as a user has it: the demo project, plus the test's driver.
    project = work / "project"
    shutil.rmtree(project, ignore_errors=True)
    shutil.copytree(repo / "client/godot", project)
    shutil.copy(repo / "tests/godot/live_link_in_godot.gd", project / "test_driver.gd")
    shutil.copy(repo / "tests/godot/hostile_messages.gd", project / "hostile_messages.gd")
    shutil.copy(repo / "tests/godot/retarget_in_godot.gd", project / "retarget_driver.gd")
    subprocess.run([str(bin_dir / "gmr"), "demo", str(work / "demo"), "--format", "gmr"], check=True,
                   capture_output=True)
    lib = env.cmu_library(work / "library")

    # (library or None for the built-in demo, (motion, roots, viewpoint, the
    # link's source_metres_per_unit, roots asked mid-stream), file for gmr
    # positions, its unit flag, restart the server)
    cases = [
        (None, ("walk", "head", "", 0, "l_toe,r_hand"), work / "demo/walk.gmr", ["--metres-per-unit", "0.01"], False),
        (None, ("wave", "", "pelvis", 0, "l_hand"), work / "demo/wave.gmr", ["--metres-per-unit", "0.01"], False),
        (lib, ("02_01", "LeftFoot", "", 0.0254, "Head"), lib / "02_01.bvh", ["--metres-per-unit", "0.0254"], True),
        (lib, ("07/07_05-walk", "lfoot", "", 0, "head,rhand"), lib / "07/07_05-walk.amc", [], False),
    ]
    failures = hostile_messages(godot, project, work)
    failures_retarget, checked_retarget = retarget_onto_character(godot, project, work, bin_dir, lib, np)
    failures += failures_retarget
    checked = 0
    for library, case, path, unit, restart in cases:
        motion, roots, viewpoint, _, new_roots = case
        label = f"{motion} (roots '{roots}', viewpoint '{viewpoint}', then roots '{new_roots}')"
        out = work / (motion.replace("/", "_") + ".json")
        for stale in (out, pathlib.Path(str(out) + ".restart")):
            stale.unlink(missing_ok=True)
        with env.Server(bin_dir, library=library, http=True) as server:
            http_port = server.http_port

            def restart_with():
                server.stop()
                return env.Server(bin_dir, library=library, http=http_port)

            result, log = run_godot(godot, project, out, http_port, case, restart_with if restart else None)
        if result is None or result["error"]:
            failures.append(f"{label}: Godot did not finish: {result and result['error']}\n{log[-3000:]}")
            continue
        if "SCRIPT ERROR" in log:
            failures.append(f"{label}: Godot reported a script error:\n{log[-3000:]}")

        def expected(roots_list):
            flags = ["--conventions", "godot", *unit]
            if roots_list:
                flags += ["--roots", roots_list]
            if viewpoint:
                flags += ["--relative-to", viewpoint]
            return env.gmr_positions(bin_dir, path, *flags)

        phases = [("before", roots), ("after", new_roots)] + ([("reconnected", new_roots)] if restart else [])
        worst_case = 0.0
        for phase, roots_list in phases:
            want, names = expected(roots_list)
            samples = [s for s in result["samples"] if s["phase"] == phase]
            if len(samples) < FRAMES:
                failures.append(f"{label}: only {len(samples)} frames applied in phase '{phase}'")
            for s in samples:
                heads = s["heads"]
                if sorted(heads) != sorted(names):
                    failures.append(f"{label} {phase}: bones {sorted(heads)[:5]}... are not the joints "
                                    f"{sorted(names)[:5]}...")
                    break
                got = np.array([[float(v) for v in heads[n]] for n in names])
                err = float(np.abs(got - want[s["frame"]]).max())
                checked += 1
                worst_case = max(worst_case, err)
                if err > TOLERANCE:
                    worst = names[int(np.abs(got - want[s["frame"]]).max(axis=1).argmax())]
                    failures.append(f"{label} {phase}: frame {s['frame']}: a bone is {err:.3g} m off "
                                    f"(bone {worst}; allowed {TOLERANCE})")
                    break
        want_roots = sorted(r.strip() for r in new_roots.split(","))
        if sorted(result["roots_after"]) != want_roots:
            failures.append(f"{label}: the Skeleton's roots after the change are {result['roots_after']}, "
                            f"not {want_roots}")
        if len(result["versions"]) < 2 or result["versions"][0] == result["versions"][1]:
            failures.append(f"{label}: the skeleton was not rebuilt with a new version: {result['versions']}")
        if restart and sorted(result["roots_property"].split(",")) != want_roots:
            failures.append(f"{label}: after reconnecting the link's roots are '{result['roots_property']}'")
        if result["bad_messages"] != 0:
            failures.append(f"{label}: the link counted {result['bad_messages']} bad messages from the server")
        if abs(result["metres_per_unit"] - 1.0) > 1e-12:
            failures.append(f"{label}: the skeleton was sent in units of {result['metres_per_unit']} m, not metres")
        last = result["samples"][-1] if result["samples"] else {}
        print(f"{label}: " + ", ".join(f"{p}: {sum(s['phase'] == p for s in result['samples'])} frames"
                                       for p, _ in phases) +
              f"; received {result['frames_received']}, applied {result['frames_applied']}, dropped "
              f"{result['frames_dropped']}; largest difference {worst_case:.2g} m; {last.get('fps', 0):.0f} fps, latency {last.get('latency_ms', 0):.2f} ms")

    env.finish(failures, checked + checked_retarget, len(cases) * 2 * FRAMES + FRAMES)
    print(f"live link in Godot: {len(cases)} motions, {checked} frames checked within {TOLERANCE} m")
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
