#!/usr/bin/env bash
# Re-measure every headline result in benchmarks/results/, its charts, and then every table of
# README.md and docs/*.md (tools/doc_tables.py --write). One job after another, so that no two
# timings share the cores; each step prints what it runs, its place in the list and how long it took.
# Run from the repository's root after `make setup` (`make figures` / `make figures-quick` do both),
# on a quiet machine: every figure that a machine moves is a timing.
#
#   bash benchmarks/figures.sh            # everything (about 50 minutes on 2 cores, references cached)
#   bash benchmarks/figures.sh quick      # the timings only: frame, kd-tree, frontier, quick start
#   bash benchmarks/figures.sh STEP ...   # the named steps (bash benchmarks/figures.sh list)
#
# The Mitsuba references are cached (~/.cache/serenity/reference, or $SERENITY_CACHE): a second
# run spends about 15 minutes less. The CUDA step runs only where there is an NVIDIA GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
SER=${SER:-.venv/bin/serenity}
R=benchmarks/results

# step name | minutes on the 2-core machine from a fresh clone (references not cached) | command
STEPS=(
  "frontier|30|$PY benchmarks/bench_frontier.py --no-progress"
  "frame-traced-probes-320|1|$SER bench courtyard --frames 24 --size 320x180 --quality traced-probes --json $R/frame_bench_traced-probes_320x180.json --chart $R/frame_bench_traced-probes_320x180.png"
  "frame-traced-probes-640|1|$SER bench courtyard --frames 24 --size 640x360 --quality traced-probes --json $R/frame_bench_traced-probes_640x360.json --chart $R/frame_bench_traced-probes_640x360.png"
  "frame-lpv-fast-320|1|$SER bench courtyard --frames 24 --size 320x180 --quality lpv-fast --json $R/frame_bench_lpv-fast_320x180.json --chart $R/frame_bench_lpv-fast_320x180.png"
  "frame-lpv-fast-640|1|$SER bench courtyard --frames 24 --size 640x360 --quality lpv-fast --json $R/frame_bench_lpv-fast_640x360.json --chart $R/frame_bench_lpv-fast_640x360.png"
  "frame-repeat|2|$PY benchmarks/bench_frame_repeat.py --runs 5 --size 320x180 --quality lpv-fast"
  "frame-threads|1|$PY benchmarks/bench_frame_threads.py --frames 60"
  "render-output|1|$SER render courtyard --size 640x360 --frames 2 --json $R/render_output.json"
  "kdtree|3|$PY benchmarks/bench_kdtree.py --json $R/kdtree.json"
  "kdtree-repeat|2|$PY benchmarks/bench_kdtree.py --build-sizes '' --json $R/kdtree_repeat.json --charts serenity_out/kdtree_repeat"
  "kdtree-phases|1|$PY benchmarks/kdtree_phases.py --json $R/kdtree_phases.json"
  "kdtree-counts|2|$PY benchmarks/kdtree_counts.py --json $R/kdtree_counts.json"
  "tracer-scheduling|4|$PY benchmarks/bench_tracer_nice.py --frames 24 --passes 10 --json $R/tracer_nice.json --chart $R/tracer_nice.png"
  "tracer-scheduling-busy|4|$PY benchmarks/bench_tracer_nice.py --frames 24 --passes 10 --load 1 --json $R/tracer_nice_load1.json --chart $R/tracer_nice_load1.png"
  "baseline|3|$PY benchmarks/bench_baseline.py"
  "lpv-room|6|$PY benchmarks/bench_lpv_room.py"
  "lpv|4|$PY benchmarks/bench_lpv.py --json $R/lpv.json"
  "stability|2|$PY benchmarks/bench_stability.py"
  "temporal-stability|20|$PY benchmarks/bench_stability.py --temporal"
  "amortise|2|$PY benchmarks/bench_amortise.py"
  "aa|2|$PY benchmarks/bench_aa.py"
  "startup|3|$PY benchmarks/bench_startup.py --runs 2"
  "lod|2|$PY benchmarks/bench_lod.py"
  "dynamic-tracing|3|$PY benchmarks/bench_dynamic.py"
  "sky|2|$PY benchmarks/bench_sky.py --json $R/sky.json --chart $R/sky.png"
  "sky-sh|1|$PY benchmarks/bench_sky_sh.py"
  "sky-anchor|1|$PY benchmarks/bench_sky_anchor.py"
  "view|1|xvfb-run -a $PY benchmarks/bench_view.py"
  "sweep-day|4|$PY examples/sweep_day.py --workers 2"
  "hero-image|1|$PY tools/hero_image.py"
  "cuda|2|$PY benchmarks/bench_cuda.py"
)
QUICK="frontier frame-traced-probes-320 frame-traced-probes-640 frame-lpv-fast-320 frame-lpv-fast-640 frame-repeat frame-threads render-output kdtree kdtree-repeat kdtree-phases"

names() { for s in "${STEPS[@]}"; do echo "${s%%|*}"; done; }
field() {  # field STEP m|c: the step's minutes or its command ('' for no such step)
  local s m c
  for s in "${STEPS[@]}"; do
    if [ "${s%%|*}" = "$1" ]; then
      IFS='|' read -r _ m c <<<"$s"
      if [ "$2" = m ]; then echo "$m"; else echo "$c"; fi
    fi
  done
  return 0
}

case "${1:-all}" in
  all) picked=$(names) ;;
  quick) picked=$QUICK ;;
  list) for n in $(names); do printf '%-24s ~%2s min  %s\n' "$n" "$(field "$n" m)" "$(field "$n" c)"; done; exit 0 ;;
  *) picked="$*" ;;
esac
for n in $picked; do
  [ -n "$(field "$n" c)" ] || { echo "figures: unknown step '$n' (bash benchmarks/figures.sh list)" >&2; exit 2; }
done

total=0; for n in $picked; do total=$((total + $(field "$n" m))); done
count=$(echo $picked | wc -w); k=0; t_all=$SECONDS
echo "figures: $count steps, about $total minutes on 2 cores from a fresh clone (less with the references cached)"
for n in $picked; do
  k=$((k + 1)); cmd=$(field "$n" c)
  if [ "$n" = cuda ] && ! nvidia-smi -L >/dev/null 2>&1; then
    echo "[$k/$count] $n: skipped (no NVIDIA GPU here; $R/cuda.json keeps its last run)"; continue
  fi
  if [ "$n" = hero-image ] && [ ! -f tools/hero_image.py ]; then
    echo "[$k/$count] $n: skipped (no tools/hero_image.py)"; continue
  fi
  echo "[$k/$count] $n (~$(field "$n" m) min): $cmd"
  t0=$SECONDS
  eval "$cmd"
  echo "[$k/$count] $n done in $((SECONDS - t0)) s ($(( (SECONDS - t_all) / 60 )) min so far)"
done
echo "figures: the tables of README.md and docs/*.md"
$PY tools/doc_tables.py --write
echo "figures: done in $(( (SECONDS - t_all) / 60 )) min; review with git diff, then commit benchmarks/results, docs and README.md"
