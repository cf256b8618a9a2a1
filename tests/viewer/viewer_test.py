"""The browser viewer in a real headless Chromium (Debian's), against a real
gmr-server serving a real CMU capture: the page's motion list, the joints it
draws (read back from its three.js scene objects) against `gmr positions`
of the same frames, a click on a joint that makes it the root, the view
from a joint against `gmr positions --relative-to`, and the motion put on
another skeleton of the library (a Mixamo rig) beside the source against
`gmr retarget`. Saves a screenshot and fails on a blank canvas.

  viewer_test.py --bin-dir BUILD/bin [--screenshot FILE]

Exit 77 (skipped) outside CI when Chromium or the corpus is missing; under
CI=true that is a failure."""

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "python"))
import gmr_test_env as env  # noqa: E402

import cdp  # noqa: E402

MOTION = "02_01"
PICKED = "LeftForeArm"     # clicked, then made the root
VIEWPOINT = "Head"         # clicked, then seen from
RIG = "rigs/Beta_jump"     # the skeleton the motion is retargeted onto, beside the source


def check(condition, message):
    if not condition:
        raise AssertionError(message)


def compare(drawn, expected, names, frame, size, what):
    """Every drawn joint against the expected positions of `frame`, to 1e-4 of the skeleton's size."""
    tolerance = 1e-4 * size
    check(set(drawn) == set(names), f"{what}: the page drew {sorted(drawn)}, expected the joints {sorted(names)}")
    worst = 0.0
    for j, name in enumerate(names):
        d = max(abs(a - b) for a, b in zip(drawn[name], expected[frame, j]))
        worst = max(worst, d)
        check(d <= tolerance, f"{what}, frame {frame}: {name} drawn at {drawn[name]}, gmr positions says "
                              f"{list(expected[frame, j])} (off by {d:.3g}, tolerance {tolerance:.3g})")
    return worst


def sample(browser, panel, count, expected, names, size, what, version=None):
    """`count` drawn frames of `panel` (distinct frame indices), each compared."""
    seen = set()
    worst = 0.0
    deadline = time.monotonic() + 30
    while len(seen) < count:
        check(time.monotonic() < deadline, f"{what}: only {len(seen)} distinct frames drawn in 30 s")
        s = browser.evaluate("gmrViewer.state()")
        d = s[panel]
        if d["frame"] is None or d["frame"] in seen or (version is not None and d["version"] == version):
            time.sleep(0.05)
            continue
        worst = max(worst, compare(d["joints"], expected, names, d["frame"], size, what))
        seen.add(d["frame"])
    print(f"{what}: {len(seen)} frames ({sorted(seen)[:3]}...) match gmr positions, worst {worst:.3g} "
          f"(tolerance {1e-4 * size:.3g})")
    return s


def non_background_pixels(browser, canvas_id):
    """Pixels of a WebGL canvas that differ from its clear colour (read back through a 2D canvas)."""
    return browser.evaluate(f"""(() => {{
      const src = document.getElementById('{canvas_id}');
      const c = document.createElement('canvas');
      c.width = src.width; c.height = src.height;
      const g = c.getContext('2d');
      g.drawImage(src, 0, 0);
      const d = g.getImageData(0, 0, c.width, c.height).data;
      let n = 0;
      for (let i = 0; i < d.length; i += 4) {{
        if (Math.abs(d[i] - 0x14) + Math.abs(d[i + 1] - 0x17) + Math.abs(d[i + 2] - 0x1c) > 24) n++;
      }}
      return n;
    }})()""")


def click_joint(browser, panel, joint):
    p = browser.evaluate(f"gmrViewer.screenPosition('{panel}', '{joint}')")
    check(p is not None, f"{joint} is not drawn in the {panel} panel")
    browser.click(p["x"], p["y"])
    browser.wait_for(f"gmrViewer.state().selected === '{joint}'", 10, f"the click on {joint} to select it")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--bin-dir", required=True)
    parser.add_argument("--screenshot", default=None)
    args = parser.parse_args()

    try:
        import numpy  # noqa: F401
        import prometheus_client.parser  # noqa: F401
    except ImportError as e:
        env.skip_or_fail(f"{e.name} is missing (scripts/install-deps.sh installs python3-numpy and "
                         "python3-prometheus-client)")
    chromium = cdp.find_chromium()
    if chromium is None:
        env.skip_or_fail("no chromium on PATH (scripts/install-deps.sh installs Debian's)")
    bvh = env.data_dir() / "bvh" / "cmu" / f"{MOTION}.bvh"
    rig = env.data_dir() / "bvh" / "mixamo" / "Beta_jump.bvh"
    for f in (bvh, rig):
        if not f.is_file():
            env.skip_or_fail(f"{f} is missing (the corpus in ../shared/data)")

    library = tempfile.TemporaryDirectory(prefix="gmr_viewer_lib_")
    (pathlib.Path(library.name) / bvh.name).symlink_to(bvh)
    (pathlib.Path(library.name) / "rigs").mkdir()
    (pathlib.Path(library.name) / "rigs" / rig.name).symlink_to(rig)
    expected, names = env.gmr_positions(args.bin_dir, bvh)
    frame0 = expected[0]
    size = float(((frame0.max(axis=0) - frame0.min(axis=0)) ** 2).sum() ** 0.5)

    with env.Server(args.bin_dir, library=library.name, http=True) as server:
        browser = cdp.Chromium(chromium)
        try:
            base = f"http://127.0.0.1:{server.http_port}/"
            browser.navigate(base)
            motions = browser.wait_for("gmrViewer.state().motions.length && gmrViewer.state().motions", 30,
                                       "the motion list")
            check(motions == [MOTION, RIG], f"the page lists {motions}, the server serves [{MOTION}, {RIG}]")
            listed = browser.evaluate("[...document.querySelectorAll('#motions li')].map(li => li.dataset.motion)")
            check(listed == [MOTION, RIG], f"the page shows {listed}")
            browser.wait_for("gmrViewer.state().world.frame !== null", 30, "the first frame drawn")

            # 1. The world panel plays the motion where gmr positions puts it.
            s = sample(browser, "world", 5, expected, names, size, "world")
            check(s["roots"] == ["Hips"], f"roots before the click: {s['roots']}")

            # 2. The transport: a click on the seek bar's middle jumps there, pause stops the frames.
            frames = len(expected)
            box = browser.evaluate("(() => { const r = document.getElementById('seek').getBoundingClientRect();"
                                   " return {x: r.left, y: r.top + r.height / 2, w: r.width}; })()")
            browser.click(box["x"] + box["w"] * 0.5, box["y"])
            target = int(browser.evaluate("Number(document.getElementById('seek').value)"))
            check(abs(target - (frames - 1) / 2) <= frames * 0.05, f"the seek bar's middle is frame {target}")
            browser.wait_for(f"(f => f >= {target} && f < {target} + 60)(gmrViewer.state().world.frame)", 10,
                             f"the world panel to jump to frame {target}")
            browser.click_element("#play")
            browser.wait_for("document.getElementById('play').textContent === 'Play'", 10, "pause")
            time.sleep(0.3)
            paused_at = browser.evaluate("gmrViewer.state().world.frame")
            time.sleep(0.5)
            check(browser.evaluate("gmrViewer.state().world.frame") == paused_at, "frames still arrive when paused")
            print(f"seek to frame {target}: drawn; pause holds frame {paused_at}")

            # 3. Click a joint, make it the root.
            click_joint(browser, "world", PICKED)
            browser.click_element("#btn-shift")
            browser.wait_for(f"JSON.stringify(gmrViewer.state().roots) === '[\"{PICKED}\"]'", 10,
                             f"the server's view to report {PICKED} as the root")
            old_version = s["world"]["version"]
            browser.click_element("#play")
            browser.wait_for("document.getElementById('play').textContent === 'Pause'", 10, "play")
            rooted, rooted_names = env.gmr_positions(args.bin_dir, bvh, "--roots", PICKED)
            s = sample(browser, "world", 5, rooted, rooted_names, size, f"world, rooted at {PICKED}",
                       version=old_version)
            check(s["world"]["version"] != old_version, "the skeleton version did not change with the root")

            # 4. The view from a joint: click it, tick the toggle.
            browser.click_element("#play")
            browser.wait_for("document.getElementById('play').textContent === 'Play'", 10, "pause")
            time.sleep(0.3)
            click_joint(browser, "world", VIEWPOINT)
            browser.click_element("#viewpoint")
            browser.wait_for(f"gmrViewer.state().viewpoint === '{VIEWPOINT}' && gmrViewer.state().joint.frame !== null",
                             20, "the view from the joint drawn")
            browser.click_element("#play")
            seen_from, seen_names = env.gmr_positions(args.bin_dir, bvh, "--roots", PICKED, "--relative-to",
                                                      VIEWPOINT)
            s = sample(browser, "joint", 5, seen_from, seen_names, size, f"seen from {VIEWPOINT}")
            head = s["joint"]["joints"][VIEWPOINT]
            check(max(abs(v) for v in head) <= 1e-4 * size, f"{VIEWPOINT} seen from itself is at {head}")
            check(not s["errors"], f"the page reported errors: {s['errors']}")

            # 5. The motion on the Mixamo rig beside the source (the server retargets it).
            browser.evaluate(f"(() => {{ const r = document.getElementById('rig'); r.value = '{RIG}';"
                             " r.dispatchEvent(new Event('change')); })()")
            browser.wait_for(f"gmrViewer.state().rig === '{RIG}' && gmrViewer.state().joint.frame !== null", 20,
                             "the motion drawn on the rig")
            with tempfile.TemporaryDirectory(prefix="gmr_viewer_rig_") as tmp:
                out = pathlib.Path(tmp) / "on_rig.bvh"
                subprocess.run([str(pathlib.Path(args.bin_dir) / "gmr"), "retarget", str(bvh), str(out),
                                "--target", str(rig)], check=True, capture_output=True)
                on_rig, rig_names = env.gmr_positions(args.bin_dir, out)
            rig0 = on_rig[0]
            rig_size = float(((rig0.max(axis=0) - rig0.min(axis=0)) ** 2).sum() ** 0.5)
            s = sample(browser, "joint", 5, on_rig, rig_names, rig_size, f"on {RIG}")
            check(s["viewpoint"] is None and s["world"]["joints"].keys() == set(seen_names),
                  "the left panel no longer shows the source")
            check(not s["errors"], f"the page reported errors: {s['errors']}")

            # 6. Something is drawn, and a screenshot shows it.
            time.sleep(2.2)  # a whole second of figures on screen
            figures = browser.evaluate("gmrViewer.state().figures")
            # (How many of the 120 a busy machine's software-rendered tab takes in varies: some.)
            check(figures["fps"] > 0, f"live figures: {figures}")
            print(f"live figures: {figures['fps']:.1f} frames/s received, {figures['drops']} drops, "
                  f"{figures['stale']} late")
            world_pixels = non_background_pixels(browser, "world-canvas")
            joint_pixels = non_background_pixels(browser, "joint-canvas")
            print(f"non-background pixels: world {world_pixels}, from the joint {joint_pixels}")
            check(world_pixels > 500 and joint_pixels > 500,
                  f"a canvas is blank: world {world_pixels}, joint {joint_pixels} non-background pixels")
            shot = pathlib.Path(args.screenshot or pathlib.Path(tempfile.gettempdir()) / "gmr_viewer.png")
            browser.screenshot(shot)
            check(shot.stat().st_size > 10000, f"the screenshot {shot} is {shot.stat().st_size} bytes")
            print(f"screenshot: {shot}")
            # 7. The page's traffic, as /metrics reports it.
            samples, _ = env.scrape_metrics(server.http_port)
            ws = (("transport", "websocket"),)
            check(samples.get(("gmr_connections", ws)) == 1, "gmr_connections{transport=websocket} is not 1")
            check(samples.get(("gmr_subscriptions", ws)) == 2,
                  f"gmr_subscriptions{{transport=websocket}}: {samples.get(('gmr_subscriptions', ws))}")
            sent = samples.get(("gmr_frames_sent_total", ws), 0)
            check(sent >= 20, f"gmr_frames_sent_total{{transport=websocket}}: {sent}")
            print(f"/metrics: {sent:.0f} frames sent over the page's WebSocket")
            errors = [line for line in browser.console if "exception" in line or "Error" in line]
            check(not errors, f"the page's console: {errors}")
        finally:
            browser.close()
        # 8. The screenshot recipe docs/viewer.md gives (scripts/viewer-screenshot.py) draws the skeleton.
        recipe = pathlib.Path(tempfile.gettempdir()) / "gmr_viewer_recipe.png"
        script = pathlib.Path(__file__).resolve().parents[2] / "scripts" / "viewer-screenshot.py"
        run = subprocess.run([sys.executable, str(script), f"http://127.0.0.1:{server.http_port}/", str(recipe),
                              "--viewpoint", VIEWPOINT, "--seconds", "0.5"], capture_output=True, text=True,
                             timeout=120)
        check(run.returncode == 0, f"scripts/viewer-screenshot.py: {run.stdout}{run.stderr}")
        check(recipe.stat().st_size > 10000, f"the recipe's screenshot is {recipe.stat().st_size} bytes")
        print(f"screenshot recipe: {run.stdout.strip()}")
    print("viewer: OK")


if __name__ == "__main__":
    try:
        main()
    except AssertionError as e:
        print(f"FAIL: {e}", file=sys.stderr)
        sys.exit(1)
