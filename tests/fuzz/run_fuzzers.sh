#!/usr/bin/env bash
# Runs every bin/fuzz_* for a bounded time from its seed corpus (tests/fuzz/corpus/<name>: tiny
# valid files plus the inputs of past findings). Any crash, timeout, leak or sanitizer report
# fails the run; crashing inputs are kept in <bin>/../fuzz_artifacts/ for turning into regression
# tests.
# The random seed is fixed (FUZZ_SEED, default 1) so a CI run explores the same inputs as a local
# run of at least the same length; set FUZZ_SEED=0 for a fresh random seed.
set -euo pipefail
bin_dir=$1
seconds=${2:-30}
seed=${FUZZ_SEED:-1}
here=$(cd "$(dirname "$0")" && pwd)
artifacts=$(cd "$bin_dir/.." && pwd)/fuzz_artifacts
mkdir -p "$artifacts"
status=0
for fuzzer in "$bin_dir"/fuzz_*; do
  [ -x "$fuzzer" ] || continue
  name=$(basename "$fuzzer")
  name=${name#fuzz_}
  work=$(mktemp -d)
  if [ -d "$here/corpus/$name" ]; then cp -r "$here/corpus/$name/." "$work/"; fi
  dict=()
  if [ -f "$here/$name.dict" ]; then dict=(-dict="$here/$name.dict"); fi
  echo "== fuzz_$name: ${seconds}s"
  if "$fuzzer" "$work" "${dict[@]}" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
       -max_len=65536 -seed="$seed" -artifact_prefix="$artifacts/${name}-" -print_final_stats=1 \
       >"$artifacts/$name.log" 2>&1; then
    grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$artifacts/$name.log" | tr '\n' ' '
    echo
  else
    echo "fuzz_$name FAILED:"; tail -40 "$artifacts/$name.log"; status=1
  fi
  rm -rf "$work"
done
exit $status
