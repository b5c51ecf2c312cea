#!/usr/bin/env bash
# Re-measure the frame's figures the README quotes (not the kd-tree's: bench_kdtree.py and its A/Bs
# are their own), one after the other so that no two timings share the cores. Run from the
# repository root after `make setup`, on a quiet machine: ~15 minutes on the 2-core machine with the
# Mitsuba references cached (~/.cache/serenity/reference), longer without.
#
#   bash benchmarks/regenerate.sh            # everything below
#   bash benchmarks/regenerate.sh frame      # the Table-1 benches (serenity bench), the 320x180 spread,
#                                            # the tracer-niceness sweep, the per-thread CPU time
#   bash benchmarks/regenerate.sh ab         # round 14-15's A/Bs, the GIL-free finish
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
    # the 320x180 bench five times (its spread), and what the tracer process's priority costs
    $PY benchmarks/bench_frame_repeat.py --runs 5 --size 320x180
    $PY benchmarks/bench_tracer_nice.py --frames 24 --passes 10 --json $R/tracer_nice.json --chart $R/tracer_nice.png
    $PY benchmarks/bench_tracer_nice.py --frames 24 --passes 10 --load 1 --json $R/tracer_nice_load1.json \
        --chart $R/tracer_nice_load1.png
    # where the frame's CPU time goes, thread by thread (the bound on what overlap can buy)
    $PY benchmarks/bench_frame_threads.py --frames 60 --json $R/frame_threads.json
}

ab() {
    # round 14's medium settings against the ones before (the README's Table-1 section), and what the
    # frame's GIL-free finish lets a worker thread do
    local P="$PY benchmarks/bench_pass_ab.py --moving --reference --frames 24"
    for sc in courtyard cornell; do
        $P --scene $sc --stage "direct lighting" --b-config shadow.contact_steps=6 \
            --b-config shadow.texels_per_pixel=2.4 --json $R/pass_ab_round14_medium_shadow_$sc.json
        $P --scene $sc --stage "direct lighting" --b-config shadow.contact_steps=3 \
            --json $R/pass_ab_round14_contact3_$sc.json
    done
    $P --stage "sky volume update" --b-config sky.sky_map_size=96 --json $R/pass_ab_round14_skymap_courtyard.json
    $PY benchmarks/bench_gil_finish.py
    # round 15: the low-res targets centred on llvmpipe's tiles (a = not), both sizes, the bench's path
    for size in 320x180 640x360; do
        $PY benchmarks/bench_pass_ab.py --moving --frames 40 --size $size --stage "lpv lighting" \
            --a-config lowres_tile_balance=false --json $R/pass_ab_round15_tiles_$size.json
    done
    $PY benchmarks/bench_pass_ab.py --moving --frames 40 --size 320x180 --stage "lpv lighting" \
        --a-config lowres_tile_balance=false --a-config overlap=false --b-config overlap=false \
        --json $R/pass_ab_round15_tiles_serial_320x180.json
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
    ab) ab ;;
    render) render ;;
    all) accuracy; frame; ab; render ;;
    *) echo "usage: $0 [all|frame|accuracy|ab|render]" >&2; exit 2 ;;
esac
