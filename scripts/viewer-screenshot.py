#!/usr/bin/python3
"""A screenshot of the browser viewer with the skeleton in it (docs/viewer.md,
"A screenshot without a screen").

`chromium --headless --screenshot --virtual-time-budget=5000 URL` gives the
page connected but with empty panels: virtual time runs the page's clocks
ahead without waiting for the frames the server streams over the WebSocket,
so the budget is spent before the first frame is drawn. This script runs
Debian's Chromium headless in real time, driven over the DevTools protocol
(tests/viewer/cdp.py, the browser test's driver): it opens the page, waits
until both panels have drawn a frame, lets the motion play a moment, and
saves the screenshot.

  scripts/viewer-screenshot.py http://127.0.0.1:7480/ viewer.png [--motion walk]
      [--viewpoint head] [--seconds 1]

Exit status 0 with the PNG written; 1 with the reason when the page never
drew (no server, no motion, no WebGL) or Chromium is missing.
"""
import argparse
import pathlib
import sys
import time
import urllib.parse

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests" / "viewer"))
import cdp  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url", help="the viewer's address, e.g. http://127.0.0.1:7480/ (a #token=... fragment is kept)")
    parser.add_argument("out", help="the PNG to write")
    parser.add_argument("--motion", help="the motion to show (default: the page's first)")
    parser.add_argument("--viewpoint", help="a joint to see the motion from in the right panel (clicked, as a user "
                                            "would)")
    parser.add_argument("--seconds", type=float, default=1.0, help="how long the motion plays before the shot")
    parser.add_argument("--width", type=int, default=1400)
    parser.add_argument("--height", type=int, default=800)
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the first frame")
    args = parser.parse_args()

    chromium = cdp.find_chromium()
    if chromium is None:
        sys.exit("viewer-screenshot: no chromium on PATH (scripts/install-deps.sh installs Debian's)")
    url = args.url
    if args.motion:
        parts = urllib.parse.urlsplit(url)
        query = urllib.parse.urlencode({"motion": args.motion})
        url = urllib.parse.urlunsplit((parts.scheme, parts.netloc, parts.path or "/", query, parts.fragment))
    browser = cdp.Chromium(chromium, args.width, args.height)
    try:
        browser.navigate(url)
        try:
            browser.wait_for("window.gmrViewer && gmrViewer.state().world.frame !== null", args.timeout,
                             "the first frame drawn")
            if args.viewpoint:
                joint = args.viewpoint.replace("'", "")
                # Paused, so the joint is where it was drawn when clicked.
                browser.click_element("#play")
                browser.wait_for("document.getElementById('play').textContent === 'Play'", 10, "pause")
                time.sleep(0.3)
                for attempt in range(3):  # a busy machine may draw the paused frame late: look again
                    p = browser.evaluate(f"gmrViewer.screenPosition('world', '{joint}')")
                    if p is None:
                        sys.exit(f"viewer-screenshot: no joint '{joint}' is drawn")
                    browser.click(p["x"], p["y"])
                    try:
                        browser.wait_for(f"gmrViewer.state().selected === '{joint}'", 3, f"a click to select {joint}")
                        break
                    except TimeoutError:
                        if attempt == 2:
                            raise
                browser.click_element("#viewpoint")
                browser.click_element("#play")
                browser.wait_for("gmrViewer.state().joint.frame !== null", args.timeout, "the view from the joint")
        except TimeoutError as e:
            sys.exit(f"viewer-screenshot: {url}: {e}")
        time.sleep(args.seconds)
        out = pathlib.Path(args.out)
        browser.screenshot(out)
        state = browser.evaluate("gmrViewer.state().world")
        print(f"{out}: {out.stat().st_size} bytes, frame {state['frame']} of the world panel")
    finally:
        browser.close()


if __name__ == "__main__":
    main()
