"""gmr-server's operator surface scraped as Prometheus would: /metrics parsed
by the Prometheus client library's own parser (Debian's
python3-prometheus-client) while TCP and UDP streams flow, /healthz and
/readyz, the HTTP errors.

  metrics_test.py --bin-dir BUILD/bin --python-dir BUILD/python

Exit 77 (skipped) outside CI when prometheus_client, numpy or protobuf is
missing; under CI=true that is a failure."""

import argparse
import math
import pathlib
import sys
import time
import unittest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "python"))
import gmr_test_env as env  # noqa: E402

ARGS = None


get = env.http_get
scrape = env.scrape_metrics


def value(samples, name, **labels):
    return samples.get((name, tuple(sorted(labels.items()))))


class Metrics(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.server = env.Server(ARGS.bin_dir, "--io-threads", "3", "--anonymous", "publish", http=True)
        cls.client = gmr_client.Client(port=cls.server.port, name="metrics test")

    @classmethod
    def tearDownClass(cls):
        cls.client.close()
        cls.server.stop()

    def test_health_and_readiness(self):
        self.assertEqual(get(self.server.http_port, "/healthz")[::2], (200, "ok\n"))
        status, _, body = get(self.server.http_port, "/readyz")
        self.assertEqual((status, body), (200, "ready: 4 motions\n"))

    def test_http_errors_say_what(self):
        port = self.server.http_port
        self.assertEqual(get(port, "/no-such-file.js")[0], 404)
        self.assertEqual(get(port, "/metrics", method="POST")[0], 405)
        status, _, body = get(port, "/ws")
        self.assertEqual(status, 426)
        self.assertIn("gmr.stream.v1.json", body)

    def test_counters_move_as_frames_flow(self):
        c = self.client
        before, types = scrape(self.server.http_port)
        for name, kind in [("gmr_frames_sent", "counter"), ("gmr_frames_computed", "counter"),
                           ("gmr_request_duration_seconds", "histogram"), ("gmr_frame_wait_seconds", "histogram"),
                           ("gmr_tick_lateness_seconds", "histogram"), ("gmr_connections", "gauge"),
                           ("gmr_subscriptions", "gauge"), ("gmr_ready", "gauge")]:
            self.assertEqual(types.get(name), kind, name)
        self.assertEqual(value(before, "gmr_ready"), 1)
        self.assertEqual(value(before, "gmr_library_motions"), 4)
        self.assertGreaterEqual(value(before, "gmr_connections", transport="tcp"), 1)
        # Three I/O threads, and each TCP connection counted on one of them.
        self.assertEqual(types.get("gmr_io_threads"), "gauge")
        self.assertEqual(value(before, "gmr_io_threads"), 3)
        per_thread = [value(before, "gmr_io_thread_connections", thread=str(t)) for t in range(3)]
        self.assertEqual(sum(per_thread), value(before, "gmr_connections", transport="tcp"), per_thread)

        tcp = c.subscribe(c.create_view("walk").id, loop=True)
        udp = c.subscribe(c.create_view("wave").id, loop=True, udp=True)
        with self.assertRaises(gmr_client.GmrError):
            c.create_view("no such motion")
        got = {"tcp": 0, "udp": 0}
        deadline = time.monotonic() + 10
        while min(got.values()) < 30:
            self.assertLess(time.monotonic(), deadline, f"frames received in 10 s: {got}")
            c.poll(0.05)
            got["tcp"] += len(tcp.frames())
            got["udp"] += len(udp.frames())
        during, during_types = scrape(self.server.http_port)
        self.assertEqual(value(during, "gmr_subscriptions", transport="tcp"), 1)
        self.assertEqual(value(during, "gmr_subscriptions", transport="udp"), 1)
        self.assertEqual(value(during, "gmr_views"), 2)
        self.assertGreaterEqual(value(during, "gmr_streams"), 2)
        for transport in ("tcp", "udp"):
            sent = value(during, "gmr_frames_sent_total", transport=transport) - \
                value(before, "gmr_frames_sent_total", transport=transport)
            self.assertGreaterEqual(sent, 30, transport)
        self.assertGreater(value(during, "gmr_frames_computed_total"), value(before, "gmr_frames_computed_total"))
        self.assertGreater(value(during, "gmr_frames_encoded_total"), value(before, "gmr_frames_encoded_total"))
        # Both streams are float32: every frame they sent was read from a
        # block of 16 frames computed for it or kept from before.
        self.assertEqual(types.get("gmr_fk_blocks_computed"), "counter")
        self.assertEqual(types.get("gmr_fk_block_bytes"), "gauge")
        fk_frames = sum(value(during, name) - (value(before, name) or 0)
                        for name in ("gmr_fk_blocks_computed_total", "gmr_fk_block_hits_total"))
        self.assertGreaterEqual(fk_frames, 60)
        self.assertGreater(value(during, "gmr_fk_blocks_computed_total"), 0)
        self.assertGreater(value(during, "gmr_fk_block_bytes"), 0)
        self.assertGreater(value(during, "gmr_bytes_sent_total", transport="tcp"),
                           value(before, "gmr_bytes_sent_total", transport="tcp"))
        # UDP bytes too: every frame of the demo's wave (float32 positions of
        # all its joints) is more than 100 bytes.
        udp_frames = value(during, "gmr_frames_sent_total", transport="udp") - \
            value(before, "gmr_frames_sent_total", transport="udp")
        self.assertGreaterEqual(value(during, "gmr_bytes_sent_total", transport="udp") -
                                value(before, "gmr_bytes_sent_total", transport="udp"), 100 * udp_frames)
        # This client's own tail: its p99 frame wait, seconds, as the upper
        # bound of a power-of-two bucket of microseconds (at most 2^18 us).
        self.assertEqual(during_types.get("gmr_client_frame_wait_p99_seconds"), "gauge")
        self.assertGreaterEqual(value(during, "gmr_clients_sent_frames"), 1)
        tail = [value(during, "gmr_client_frame_wait_p99_seconds", clients=c)
                for c in ("median", "worst_1_percent", "worst")]
        self.assertTrue(1e-6 <= tail[0] <= tail[1] <= tail[2] <= 0.263, tail)
        self.assertEqual(round(math.log2(tail[2] * 1e6), 6) % 1, 0, tail)
        self.assertEqual(types.get("gmr_multicast_frames_sent"), "counter")
        self.assertEqual(value(during, "gmr_multicast_frames_sent_total"), 0)  # no --multicast-group
        self.assertEqual((value(during, "gmr_request_errors_total", code="NOT_FOUND") or 0) -
                         (value(before, "gmr_request_errors_total", code="NOT_FOUND") or 0), 1)
        self.assertGreaterEqual(value(during, "gmr_requests_total", request="subscribe"), 2)
        self.assertGreater(value(during, "gmr_request_duration_seconds_count"),
                           value(before, "gmr_request_duration_seconds_count"))
        self.assertGreater(value(during, "gmr_tick_lateness_seconds_count"),
                           value(before, "gmr_tick_lateness_seconds_count") or 0)
        self.assertGreater(value(during, "gmr_frame_wait_seconds_count", transport="tcp"), 0)

        # Half a second later the counters have moved on, not back.
        time.sleep(0.5)
        while tcp.latest() is None:
            c.poll(0.05)
        c.poll(0.2)
        after, _ = scrape(self.server.http_port)
        for key, v in during.items():
            if key[0].endswith("_total") or key[0].endswith("_count"):
                self.assertGreaterEqual(after.get(key, 0), v, key)
        self.assertGreater(value(after, "gmr_frames_sent_total", transport="tcp"),
                           value(during, "gmr_frames_sent_total", transport="tcp"))
        tcp.unsubscribe()
        udp.unsubscribe()
        ended, _ = scrape(self.server.http_port)
        self.assertEqual(value(ended, "gmr_subscriptions", transport="tcp"), 0)
        self.assertEqual(value(ended, "gmr_subscriptions", transport="udp"), 0)

    def test_live_sources_are_counted(self):
        before, types = scrape(self.server.http_port)
        self.assertEqual(types.get("gmr_live_sources"), "gauge")
        self.assertEqual(types.get("gmr_live_frames_received"), "counter")
        self.assertEqual(types.get("gmr_live_frames_refused"), "counter")
        with gmr_client.Client(port=self.server.port, name="metrics publisher") as p:
            pub = p.publish("metrics/live", gmr_client.Skeleton.points(["a", "b"]), 1 / 60)
            for k in range(5):
                p.publish_frame(pub, [k, 0, 0, 0, k, 0])
            p.publish_frame(pub, [0, 0, 0, 0, float("inf"), 0])
            errors = []
            deadline = time.monotonic() + 5
            while not errors and time.monotonic() < deadline:
                p.poll(0.05)
                errors += p.take_errors()
            self.assertEqual(len(errors), 1, errors)
            during, _ = scrape(self.server.http_port)
            self.assertEqual(value(during, "gmr_live_sources"), value(before, "gmr_live_sources") + 1)
            self.assertEqual(value(during, "gmr_live_frames_received_total") -
                             value(before, "gmr_live_frames_received_total"), 5)
            self.assertEqual(value(during, "gmr_live_frames_refused_total") -
                             value(before, "gmr_live_frames_refused_total"), 1)
            p.unpublish(pub)
        after, _ = scrape(self.server.http_port)
        self.assertEqual(value(after, "gmr_live_sources"), value(before, "gmr_live_sources"))


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--bin-dir", required=True)
    parser.add_argument("--python-dir", required=True)
    ARGS, rest = parser.parse_known_args()
    try:
        import numpy  # noqa: F401
        import google.protobuf  # noqa: F401
        import prometheus_client.parser  # noqa: F401
    except ImportError as e:
        env.skip_or_fail(f"{e.name} is missing (scripts/install-deps.sh installs python3-prometheus-client, "
                         "python3-numpy and python3-protobuf)")
    sys.path.insert(0, ARGS.python_dir)
    import gmr_client  # noqa: E402
    unittest.main(argv=[sys.argv[0]] + rest, verbosity=2)
