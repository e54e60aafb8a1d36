#!/usr/bin/env bash
# Compares lockstep_bench binaries on a noisy machine: runs each in turn,
# ROUNDS times, each run 10 short repetitions of the benchmarks that FILTER
# selects, pinned to one core, and prints per benchmark and binary the
# smallest ns_per_copy or ns_per_env_step seen. Interference from other work
# only ever adds time, so the minimum is the steadiest statistic; alternating
# the binaries spreads a slow spell over all of them.
#
#   bench/alternate.sh 'BM_aba/anymal_b' 3 /tmp/old/lockstep_bench build/release/bin/lockstep_bench
set -euo pipefail

if [[ $# -lt 3 ]]; then
  echo "usage: $0 FILTER ROUNDS BINARY [BINARY...]" >&2
  exit 2
fi
filter=$1
rounds=$2
shift 2
core=${LOCKSTEP_BENCH_CORE:-$(($(nproc) - 1))}

for ((round = 0; round < rounds; ++round)); do
  for binary in "$@"; do
    taskset -c "$core" "$binary" --benchmark_filter="$filter" --benchmark_min_time=0.05 \
      --benchmark_repetitions=10 2>/dev/null |
      awk -v binary="$binary" '
        /^BM_/ && $1 !~ /_(mean|median|stddev|cv)$/ {
          for (i = 2; i <= NF; ++i)
            if ($i ~ /^ns_per_(copy|env_step)=/) {
              value = $i
              sub(/^[a-z_]+=/, "", value)
              scale = value ~ /ks$/ ? 1000 : 1
              sub(/k?s$/, "", value)
              print $1, binary, value * scale
            }
        }'
  done
done | awk '{ key = $1 " " $2; if (!(key in best) || $3 < best[key]) best[key] = $3 }
            END { for (key in best) printf "%s %.1f\n", key, best[key] }' | sort
