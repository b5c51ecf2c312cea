#!/usr/bin/env bash
# Re-measure the frame's figures the README quotes (not the kd-tree's: bench_kdtree.py and its A/Bs
# are their own), one after the other so that no two timings share the cores. Run from the
# repository root after `make setup`, on a quiet machine: ~15 minutes on the 2-core machine with the
# Mitsuba references cached (~/.cache/serenity/reference), longer without.
#
#   bash benchmarks/regenerate.sh            # everything below
#   bash benchmarks/regenerate.sh frame      # only the Table-1 benches (serenity bench)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
SER=.venv/bin/serenity
R=benchmarks/results
what=${1:-all}

frame() {
    # Table 1 (every technique: medium, the bench's default) and low, at both sizes; the first
    # pair again a minute later, to show the run-to-run spread
    # (the README's timelines are the second run's; the others' charts stay in serenity_out/)
    $SER bench courtyard --frames 24 --size 640x360 --json $R/frame_bench_run1.json --chart serenity_out/timeline_run1.png
    $SER bench courtyard --frames 24 --size 320x180 --json $R/frame_bench_320_run1.json \
        --chart serenity_out/timeline_320_run1.png
    $SER bench courtyard --frames 24 --size 640x360 --json $R/frame_bench.json --chart docs/timeline.png
    $SER bench courtyard --frames 24 --size 320x180 --json $R/frame_bench_320.json --chart docs/timeline_320.png
    $SER bench courtyard --frames 24 --size 640x360 --quality low --json $R/frame_bench_low.json \
        --chart serenity_out/timeline_low.png
    $SER bench courtyard --frames 24 --size 320x180 --quality low --json $R/frame_bench_320_low.json \
        --chart serenity_out/timeline_320_low.png
}

accuracy() {
    $PY benchmarks/bench_lpv_room.py
    $PY benchmarks/bench_baseline.py
    $PY benchmarks/bench_stability.py
    $PY benchmarks/bench_frontier.py --no-progress
}

render() {
    # the README's quick-start output: the default preset, second frame
    $SER render courtyard --size 640x360 --frames 2 --json $R/render_output.json
}

case $what in
    frame) frame ;;
    accuracy) accuracy ;;
    render) render ;;
    all) accuracy; frame; render ;;
    *) echo "usage: $0 [all|frame|accuracy|render]" >&2; exit 2 ;;
esac
