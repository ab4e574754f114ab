#!/usr/bin/env bash
# Build tools/fast_dds_set_listener_spin.cpp against the .venv's Fast DDS (the Jazzy wheels)
# and run it: first with set_listener's default (infinite) timeout, then with a finite one.
# Each run is cut at $CUT s (default 15): a run cut there has spun in set_listener.
#   tools/fast_dds_set_listener_spin.sh [runs]      (needs g++; ./dev setup first)
set -u
here=$(cd "$(dirname "$0")/.." && pwd)
venv=$here/.venv
libs=$(dirname "$(find "$venv/lib" -name 'libtinyxml2-*.so*' | head -1)")
out=${TMPDIR:-/tmp}/fast_dds_set_listener_spin
runs=${1:-3}
cut=${CUT:-15}
g++ -std=c++17 -O1 -I"$venv/include" "$here/tools/fast_dds_set_listener_spin.cpp" -o "$out" \
    -L"$venv/lib" -lfastrtps -lfastcdr -lpthread -Wl,-rpath-link,"$libs" 2>&1 | grep -v 'warning' >&2
export LD_LIBRARY_PATH=$venv/lib:$libs
for run in $(seq "$runs"); do
  for timeout in '' 5; do
    echo "== run $run, set_listener timeout ${timeout:-default (infinite)}"
    timeout "$cut" "$out" $timeout | tail -3
    code=${PIPESTATUS[0]}
    [ "$code" = 124 ] && echo "   cut after $cut s: still in set_listener"
  done
done
