#!/usr/bin/env bash
# The server's user-space instructions per frame, counted by callgrind: a
# figure that does not move with the machine's speed, which on this VM moves
# the CPU per frame by up to 2x within a day (docs/performance.md, "Counted
# instructions"). For changes to the per-frame code above the kernel; the
# kernel's share (most of a frame's cost) is not counted.
#
#   bench/server/callgrind.sh [BUILD_DIR] [SERVER_BINARY]
#     CLIENTS=50  RATE=60  SECONDS_COUNTED=10  FLAGS=""  (gmr-load flags: --udp, --shared)
#     MOTION_FILE=../shared/data/bvh/cmu/01_01.bvh  CALLGRIND_OUT=(kept when set, for callgrind_annotate)
#
# The server (SERVER_BINARY, default BUILD_DIR/bin/gmr-server, one I/O thread)
# runs under valgrind on CPU 0 with instrumentation off; once gmr-load's
# clients (CPU 1) stream, it is switched on for SECONDS_COUNTED. Prints the
# instructions, the ticks (Stream::on_tick calls) and the frames handed to
# subscribers (TcpTarget / UdpTarget::deliver calls) in that time, and
# instructions per tick and per frame. Keep the load light: under callgrind
# the server runs about 50 times slower, and a late stream skips ticks.
set -euo pipefail
build=${1:-build}
bin="$build/bin"
server=${2:-$bin/gmr-server}
clients=${CLIENTS:-50}
rate=${RATE:-60}
counted=${SECONDS_COUNTED:-10}
read -r -a flags <<<"${FLAGS:-}"
motion_file=${MOTION_FILE:-../shared/data/bvh/cmu/01_01.bvh}
here=$(dirname "$0")
command -v valgrind >/dev/null && command -v callgrind_control >/dev/null ||
  { echo "callgrind bench: needs valgrind (Debian's valgrind)" >&2; exit 1; }
[ -x "$server" ] && [ -x "$bin/gmr-load" ] || { echo "callgrind bench: build gmr-server and gmr-load first" >&2; exit 1; }
[ -f "$motion_file" ] || { echo "callgrind bench: no $motion_file (../shared/data, or set MOTION_FILE)" >&2; exit 1; }
bench_name="callgrind bench"
# shellcheck source=bench/server/common.sh
. "$here/common.sh"

out=${CALLGRIND_OUT:-$library/callgrind.out}
taskset -c 0 valgrind --tool=callgrind --callgrind-out-file="$out" --dump-instr=no --instr-atstart=no \
  "$server" --library "$library" --port 0 --port-file "$library/port" --http-port -1 --send-budget 0 \
  --io-threads 1 --log-level warn >"$library/server.log" 2>&1 &
spid=$!
for _ in $(seq 600); do [ -s "$library/port" ] && break; sleep 0.1; done
[ -s "$library/port" ] || { echo "$bench_name: the server did not start:" >&2; cat "$library/server.log" >&2; exit 1; }
taskset -c 1 "$bin/gmr-load" --port "$(cat "$library/port")" --clients "$clients" --rate "$rate" \
  --seconds $((counted + 8)) --warmup 4 --threads 1 --motion "$motion" --timeout-ms 120000 "${flags[@]}" \
  >"$library/load.txt" 2>&1 &
lpid=$!
sleep 8  # set-up and warm-up, under valgrind
callgrind_control -i on "$spid" >/dev/null
sleep "$counted"
callgrind_control -i off "$spid" >/dev/null
wait "$lpid" || { echo "$bench_name: gmr-load failed:" >&2; cat "$library/load.txt" >&2; exit 1; }
stop_server
grep -E '^delivered|^lost' "$library/load.txt"
python3 - "$out" <<'PY'
import glob, re, sys
total = ticks = frames = 0
names = {}
for path in glob.glob(sys.argv[1] + '*'):
    callee = ''
    for line in open(path, errors='replace'):
        m = re.match(r'(c?fn)=\((\d+)\)(?: (.*))?', line)
        if m:
            if m.group(3):
                names[m.group(2)] = m.group(3)
            if m.group(1) == 'cfn':
                callee = names.get(m.group(2), '')
            continue
        if line.startswith('calls='):
            n = int(line.split('=')[1].split()[0])
            if 'Stream::on_tick()' in callee:
                ticks += n
            elif re.search(r'(Tcp|Udp)Target::deliver\(', callee):
                frames += n
        elif line.startswith(('summary:', 'totals:')):
            total = max(total, int(line.split()[1]))
print(f"instructions {total:,}, ticks {ticks:,}, frames {frames:,}: "
      f"{total / max(ticks, 1):,.0f} a tick, {total / max(frames, 1):,.0f} a frame")
PY
