#!/usr/bin/env python3
"""BVH files gmr writes, read by the programs people open them with.

For every BVH and ASF/AMC take of the corpus (../shared/data), gmr writes:
  export    the take as BVH (gmr convert)
  via-gmr   BVH -> GMR -> BVH (BVH takes only)
  shift     re-rooted at the head (gmr shift --to), one ROOT
  forest    split at an upper arm (gmr split --at): two ROOT blocks
  forest1   the same forest with --single-root: one ROOT
  retarget  CMU 02_01 put on the Character Creator and Mixamo rigs (gmr retarget),
            judged against gmr positions of that file
Blender's own importer (Debian's blender, rotation modes Quaternion and, for
the takes' own rotations, Native Euler) and three.js's BVHLoader (npm `three`,
played with an AnimationMixer) read them, and every joint's world
position in every frame must equal `gmr positions` of the original take to
1e-4 of the skeleton's size (the diagonal of its frame-0 bounding box).
Assimp (libassimp-dev, through tests/interop/assimp_bvh_positions.cpp) reads
the same files as three.js but every take. three.js and Assimp read one ROOT
only, so they get forest1 and not forest; it cannot
animate bones whose names hold one of []:/. (Mixamo's "mixamorig:Hips"), so
takes with such names are left out of its part.

  bvh_readers_test.py REPO_ROOT GMR_BIN_DIR --assimp READER [--only SUBSTRING] [--keep DIR]

Outside CI a missing corpus, Blender or node/three skips (exit 77); under
CI=true it fails.
"""
import argparse
import csv
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SKIP = 77
REL_TOL = 1e-4
MIN_TAKES = 52  # 43 BVH and 9 AMC takes in ../shared/data
# three.js's PropertyBinding treats these as separators in a track name: a
# bone named "mixamorig:Hips" is never animated, whatever file it comes from.
THREE_RESERVED = "[]:/."
IN_CI = os.environ.get("CI") == "true"
BLENDER_PROCESSES = 2


def skip_or_fail(message):
    if IN_CI:
        print(f"FAIL: {message} (CI=true: the interop test must run)")
        sys.exit(1)
    print(f"SKIP: {message}")
    sys.exit(SKIP)


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))}: exit {r.returncode}: {r.stderr.strip()[-2000:]}")
    return r.stdout


def read_positions(path_or_text, from_text=False):
    """CSV frame,joint,x,y,z -> {joint: [(x, y, z) per frame]}, joint order."""
    lines = path_or_text.splitlines() if from_text else open(path_or_text).read().splitlines()
    out, order = {}, []
    for row in csv.reader(lines[1:]):
        f, name = int(row[0]), row[1]
        seq = out.get(name)
        if seq is None:
            seq = out[name] = []
            order.append(name)
        if len(seq) != f:
            raise RuntimeError(f"{name}: frame {f} out of order")
        seq.append((float(row[2]), float(row[3]), float(row[4])))
    return out, order


def hierarchy_nodes(bvh_path):
    """Nodes of a BVH hierarchy in file order: (kind, parent index, offset)."""
    nodes, stack = [], []
    pending = None
    with open(bvh_path) as f:
        for line in f:
            t = line.split()
            if not t:
                continue
            key = t[0].upper()
            if key == "MOTION":
                break
            if key in ("ROOT", "JOINT") or (key == "END" and len(t) > 1 and t[1].upper() == "SITE"):
                pending = "end" if key == "END" else key.lower()
            elif key == "{":
                nodes.append([pending, stack[-1] if stack else -1, None])
                stack.append(len(nodes) - 1)
            elif key == "}":
                stack.pop()
            elif key == "OFFSET":
                nodes[stack[-1]][2] = tuple(float(v) for v in t[1:4])
    return nodes


def pick_joint(order, nodes, names_wanted):
    """The first joint (not an End Site) whose lower-case name contains one of
    names_wanted, tried in turn; else the joint in the middle of the file."""
    kinds = {}
    for (kind, _, _), name in zip(nodes, order):
        kinds[name] = kind
    for want in names_wanted:
        for name in order:
            if kinds.get(name) == "joint" and want in name.lower():
                return name
    joints = [n for n in order if kinds.get(n) == "joint"]
    return joints[len(joints) // 2]


def size_of(ref):
    lo = [math.inf] * 3
    hi = [-math.inf] * 3
    for seq in ref.values():
        for i in range(3):
            lo[i] = min(lo[i], seq[0][i])
            hi[i] = max(hi[i], seq[0][i])
    return math.dist(lo, hi)


def judge(reader, case, ref, got, frames, tol, failures, may_miss=frozenset()):
    """True when `got` ({reference name: positions per frame}) holds every
    reference joint but those in may_miss, each within tol of `ref` in every
    frame; else a failure is added. Joints gmr inserted (*_gmr_pre,
    gmr_world) are not in the take and not compared."""
    worst, where = 0.0, ""
    for name, seq in got.items():
        r = ref.get(name)
        if r is None:
            continue
        if len(seq) != frames:
            failures.append(f"{reader} {case}: {name} has {len(seq)} frames, expected {frames}")
            return False
        for f in range(frames):
            e = math.dist(seq[f], r[f])
            if e > worst:
                worst, where = e, f"{name} frame {f}"
    if worst > tol:
        failures.append(f"{reader} {case}: error {worst:.3g} > {tol:.3g} at {where}")
        return False
    missing = sorted(set(ref) - set(got) - set(may_miss))
    if missing:
        failures.append(f"{reader} {case}: joints not read: {missing[:5]}")
        return False
    return True


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("repo")
    ap.add_argument("bindir")
    ap.add_argument("--only", default="")
    ap.add_argument("--keep", default="")
    ap.add_argument("--assimp", default="", help="gmr_assimp_bvh_positions (built when libassimp-dev is installed)")
    args = ap.parse_args()
    repo = Path(args.repo).resolve()
    gmr = str(Path(args.bindir) / "gmr")
    data = (repo / ".." / "shared" / "data").resolve()
    if not data.is_dir():
        skip_or_fail(f"no corpus at {data}")
    blender = shutil.which("blender")
    node = shutil.which("node")
    three = repo / "tests" / "interop" / "node_modules" / "three" / "package.json"
    if not blender:
        skip_or_fail("Blender is not installed (scripts/install-deps.sh installs it)")
    if not node or not three.is_file():
        skip_or_fail("node or npm package three missing (scripts/install-deps.sh installs them)")
    if not args.assimp or not Path(args.assimp).is_file():
        skip_or_fail("the Assimp reader was not built (libassimp-dev missing at configure time)")

    takes = sorted((data / "bvh").rglob("*.bvh")) + sorted((data / "asfamc").rglob("*.amc"))
    takes = [t for t in takes if args.only in str(t)]
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="gmr-interop-"))
    work.mkdir(parents=True, exist_ok=True)

    cases = []  # (take, variant, bvh path, reference key)
    refs = {}
    failures = []
    for i, take in enumerate(takes):
        key = f"{i:02d}_{take.stem}"
        text = run([gmr, "positions", str(take)])
        ref, order = read_positions(text, from_text=True)
        frames = len(next(iter(ref.values())))
        refs[key] = (ref, frames, size_of(ref) * REL_TOL, take)
        out = work / key
        try:
            run([gmr, "convert", str(take), f"{out}.export.bvh"])
            cases.append((key, "export", f"{out}.export.bvh"))
            if take.suffix == ".bvh":
                run([gmr, "convert", str(take), f"{out}.gmr"])
                run([gmr, "convert", f"{out}.gmr", f"{out}.via-gmr.bvh"])
                cases.append((key, "via-gmr", f"{out}.via-gmr.bvh"))
            nodes = hierarchy_nodes(f"{out}.export.bvh")
            export_order = read_positions(run([gmr, "positions", f"{out}.export.bvh", "--frames", "0:1"]), True)[1]
            head = pick_joint(export_order, nodes, ["head"])
            arm = pick_joint(export_order, nodes, ["leftarm", "lhumerus", "l_upperarm", "leftshoulder", "arm"])
            run([gmr, "shift", str(take), "--to", head, "-o", f"{out}.shift.bvh"])
            cases.append((key, "shift", f"{out}.shift.bvh"))
            run([gmr, "split", str(take), "--at", arm, "-o", f"{out}.forest.bvh"])
            cases.append((key, "forest", f"{out}.forest.bvh"))
            run([gmr, "split", str(take), "--at", arm, "--single-root", "-o", f"{out}.forest1.bvh"])
            cases.append((key, "forest1", f"{out}.forest1.bvh"))
        except RuntimeError as e:
            failures.append(f"{take}: gmr failed: {e}")

    # Retargeted takes (gmr retarget, docs/retarget.md): CMU 02_01 on the
    # Character Creator and Mixamo rigs, judged against gmr's positions of the
    # retargeted file itself (so the readers see the same limb directions).
    walk = data / "asfamc" / "02" / "02_01.amc"
    for rig in (["bvh/cmu_iclone/001_01.bvh", "bvh/mixamo/Beta_jump.bvh"] if args.only in str(walk) else []):
        key = f"retarget_{Path(rig).stem}"
        out = work / key
        try:
            run([gmr, "retarget", str(walk), f"{out}.retarget.bvh", "--target", str(data / rig)])
            ref, _ = read_positions(run([gmr, "positions", f"{out}.retarget.bvh"]), from_text=True)
            refs[key] = (ref, len(next(iter(ref.values()))), size_of(ref) * REL_TOL, walk)
            cases.append((key, "retarget", f"{out}.retarget.bvh"))
        except RuntimeError as e:
            failures.append(f"{walk} onto {rig}: gmr failed: {e}")

    # gmr's names for each exported file's nodes, in file order (End Sites named as gmr reads them).
    layouts = {}
    for key, variant, bvh in cases:
        order = read_positions(run([gmr, "positions", bvh, "--frames", "0:1"]), True)[1]
        nodes = hierarchy_nodes(bvh)
        if len(order) != len(nodes):
            failures.append(f"{bvh}: gmr reads {len(order)} joints, the hierarchy has {len(nodes)} blocks")
            continue
        layouts[(key, variant)] = (order, nodes)

    # Blender reads every file with rotation mode Quaternion, and the takes'
    # own rotations (export, via-gmr) also with its default, Native Euler:
    # that mode re-expresses each rotation as Euler angles about the bone's
    # rest axes in single precision, which near gimbal lock in those axes
    # costs up to 1e-3 of the skeleton's size (docs/gmr-format.md).
    blender_runs = [(c, "QUATERNION") for c in cases] + [(c, "NATIVE") for c in cases if c[1] in ("export", "via-gmr")]
    blender_manifest, three_manifest = [], []
    for (key, variant, bvh), mode in blender_runs:
        blender_manifest.append({"bvh": bvh, "out": f"{bvh}.blender-{mode}.csv", "frames": refs[key][1], "mode": mode})
    three_cases = []
    for key, variant, bvh in cases:
        if variant == "forest":
            continue  # three.js reads one ROOT only: it gets forest1
        if any(c in name for name in refs[key][0] for c in THREE_RESERVED):
            continue  # three.js cannot animate these names, not even in the original take
        three_cases.append((key, variant, bvh))
        three_manifest.append({"bvh": bvh, "out": f"{bvh}.three.csv", "frames": refs[key][1]})
    # Assimp, like three.js, reads one ROOT only; it takes any name.
    assimp_cases = [c for c in cases if c[1] != "forest"]
    (work / "assimp.txt").write_text("".join(f"{bvh}\t{bvh}.assimp.csv\t{refs[key][1]}\n"
                                             for key, variant, bvh in assimp_cases))
    (work / "three.json").write_text(json.dumps(three_manifest))
    here = repo / "tests" / "interop"
    # The readers run at once, Blender (the slowest by far) as two processes
    # with every other file each: each writes its own CSVs, so the results do
    # not depend on the order they finish in.
    readers = [("the Assimp reader", "assimp-bvh", [args.assimp, str(work / "assimp.txt")], None)]
    for half in range(BLENDER_PROCESSES):
        manifest = work / f"blender-{half}.json"
        manifest.write_text(json.dumps(blender_manifest[half::BLENDER_PROCESSES]))
        readers.append((f"blender (part {half + 1} of {BLENDER_PROCESSES})", "blender-bvh",
                        [blender, "-b", "--factory-startup", "-noaudio", "--python",
                         str(here / "blender_bvh_positions.py"), "--", str(manifest)], None))
    readers.append(("node", "three-bvh", [node, str(here / "three_bvh_positions.mjs"), str(work / "three.json")],
                    str(here)))
    # Output goes to files: a reader blocked on a full pipe would wait for the others.
    running = []
    for i, (name, tag, cmd, cwd) in enumerate(readers):
        out_path, err_path = work / f"reader-{i}.out", work / f"reader-{i}.err"
        with open(out_path, "w") as out, open(err_path, "w") as err:
            running.append((name, tag, out_path, err_path, subprocess.Popen(cmd, stdout=out, stderr=err, cwd=cwd)))
    for name, tag, out_path, err_path, proc in running:
        proc.wait()
        out, err = out_path.read_text(errors="replace"), err_path.read_text(errors="replace")
        own = [line for line in out.splitlines() if "FAILED" in line and (tag != "blender-bvh" or line.startswith(tag))]
        failures.extend(own)
        if proc.returncode != 0 and not own:
            failures.append(f"{name} exited {proc.returncode}: {err[-2000:]}")

    checked = {"blender": set(), "three": set(), "assimp": set()}
    uncompared_end_sites = 0
    for (key, variant, bvh), mode in blender_runs:
        if (key, variant) not in layouts:
            continue
        order, nodes = layouts[(key, variant)]
        ref, frames, tol, take = refs[key]
        case = f"{take.relative_to(data)} [{variant}, {mode.lower()}]"
        # A bone per ROOT/JOINT; an End Site is its parent's tail when it is
        # the parent's only End Site and not of zero length.
        path = Path(f"{bvh}.blender-{mode}.csv")
        if not path.is_file():
            continue
        got_raw, _ = read_positions(str(path))
        got = {}
        end_sites = {}
        for i, (kind, parent, offset) in enumerate(nodes):
            if kind == "end":
                end_sites.setdefault(parent, []).append(i)
        for i, (kind, parent, offset) in enumerate(nodes):
            if kind != "end":
                got[order[i]] = got_raw.get(order[i], [])
            elif len(end_sites[parent]) == 1 and math.hypot(*offset) > 1e-3:
                got[order[i]] = got_raw.get(order[parent] + "@tail", [])
            elif mode == "QUATERNION":
                uncompared_end_sites += 1
        # End Sites Blender shows as no tail are counted above, not missing.
        end_site_names = {order[i] for i, node in enumerate(nodes) if node[0] == "end"}
        if judge("blender", case, ref, got, frames, tol, failures, end_site_names):
            checked["blender"].add((key, variant, mode))
    # three.js and Assimp: every node in file order, End Sites included.
    for reader, suffix, reader_cases in (("three.js", "three", three_cases), ("assimp", "assimp", assimp_cases)):
        for key, variant, bvh in reader_cases:
            if (key, variant) not in layouts:
                continue
            order, nodes = layouts[(key, variant)]
            ref, frames, tol, take = refs[key]
            case = f"{take.relative_to(data)} [{variant}]"
            path = Path(f"{bvh}.{suffix}.csv")
            if not path.is_file():
                continue
            got_raw, _ = read_positions(str(path))
            got = {order[k]: got_raw.get(f"#{k}", []) for k in range(len(order))}
            if judge(reader, case, ref, got, frames, tol, failures):
                checked[suffix].add((key, variant))

    n_takes = len(refs)
    three_takes = len({c[0] for c in three_cases})
    print(f"takes: {n_takes} ({three_takes} with names three.js can animate), exported files: {len(cases)}")
    print(f"blender: {len(checked['blender'])} of {len(blender_runs)} imports equal to gmr positions "
          f"({uncompared_end_sites} End Sites not shown by Blender as a bone tail)")
    print(f"three.js: {len(checked['three'])} of {len(three_cases)} files equal to gmr positions")
    print(f"assimp: {len(checked['assimp'])} of {len(assimp_cases)} files equal to gmr positions")
    if not args.only and n_takes < MIN_TAKES:
        failures.append(f"only {n_takes} takes found under {data}: the corpus has {MIN_TAKES}")
    if not failures and (len(checked["blender"]) != len(blender_runs) or len(checked["three"]) != len(three_cases)
                         or len(checked["assimp"]) != len(assimp_cases)):
        failures.append("some files were not checked")
    for f in failures:
        print(f"FAIL: {f}")
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
