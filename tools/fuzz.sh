#!/usr/bin/env bash
# Coverage-guided fuzzing of pedscan's readers with libFuzzer on stable Rust (see fuzz/README.md).
#
#   tools/fuzz.sh list                 # the fuzz targets
#   tools/fuzz.sh build                # build every target (fuzz/target, apart from the main build)
#   tools/fuzz.sh run TARGET SECONDS [FLAGS...]  # fuzz one target; new inputs go to
#                                      # fuzz/corpus/TARGET; FLAGS go to libFuzzer
#   tools/fuzz.sh ci SECONDS           # every target on its corpus, then a fixed-seed short run
#                                      # (4000 inputs per second given, at most SECONDS); fails on
#                                      # any finding
#   tools/fuzz.sh min TARGET           # minimise fuzz/corpus/TARGET in place (set cover of its edges)
#   tools/fuzz.sh repro TARGET FILE... # run the target once on each FILE (a crash reproduces)
#
# Findings (crash-*, leak-*, timeout-*, oom-*) are written to fuzz/artifacts/TARGET/.
set -euo pipefail
script=$(realpath "$0")
caller=$PWD
cd "$(dirname "$script")/../fuzz"

# The sanitizer-coverage instrumentation cargo-fuzz uses, minus its nightly-only parts
# (-Zsanitizer): edge counters and the PC table drive libFuzzer's coverage feedback,
# trace-compares lets it solve magic numbers and lengths (fuzz/Cargo.toml turns on debug
# assertions and overflow checks).
export RUSTFLAGS="--cfg fuzzing -Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares -Cllvm-args=-simplifycfg-branch-fold-threshold=0 \
-Cforce-frame-pointers=yes"
# An explicit --target keeps RUSTFLAGS off build scripts and proc macros.
triple=$(rustc -vV | sed -n 's/^host: //p')
bin_dir="${CARGO_TARGET_DIR:-target}/$triple/release"
export RUST_BACKTRACE=1

# Every target with the longest input it is given (bytes): room for the seeds and some growth,
# small enough that one execution stays quick.
targets="pcap:65536 ouster_pcap:65536 pcd:4096 kitti_bin:4096 kitti_times:2048 poses_kitti:4096 poses_tum:4096
tracks_eth:4096 tracks_eth4:4096 tracks_atc:4096 tracks_csv:4096 config_toml:4096 sensor_toml:2048
human_gltf:16384 environment_gltf:32768 rosbag:16384"
# What bounds one run: memory, seconds per input. Findings go to fuzz/artifacts/TARGET/.
limits="-rss_limit_mb=2048 -timeout=10"

die() { echo "fuzz.sh: $*" >&2; exit 2; }
max_len() {
  local t
  for t in $targets; do
    if [ "${t%%:*}" = "$1" ]; then echo "${t#*:}"; return; fi
  done
  die "no target '$1' (tools/fuzz.sh list)"
}
build() {
  # fuzz/Cargo.lock must follow the main crate's dependencies; say how when it does not.
  cargo metadata --locked --format-version 1 >/dev/null 2>&1 \
    || die "fuzz/Cargo.lock is out of date with Cargo.toml: run 'cargo fetch --manifest-path fuzz/Cargo.toml' and commit it"
  cargo build --release --locked --target "$triple" --bins
}
# The readers take paths: each process writes its inputs under TMPDIR, removed afterwards.
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
export TMPDIR="$scratch"

# fuzz TARGET SECONDS CORPUS_DIR...: the first folder receives the new inputs.
fuzz() {
  local t=$1 secs=$2
  shift 2
  mkdir -p "artifacts/$t"
  "$bin_dir/$t" "$@" -max_total_time="$secs" -max_len="$(max_len "$t")" $limits \
    -artifact_prefix="artifacts/$t/" -print_final_stats=1
}

cmd=${1:-}
case "$cmd" in
  list)
    for t in $targets; do echo "${t%%:*}"; done
    ;;
  build)
    build
    ;;
  run)
    [ $# -ge 3 ] || die "usage: tools/fuzz.sh run TARGET SECONDS [LIBFUZZER_FLAGS...]"
    t=$2 secs=$3
    shift 3
    max_len "$t" >/dev/null
    build
    mkdir -p "corpus/$t"
    fuzz "$t" "$secs" "corpus/$t" "$@"
    ;;
  ci)
    [ $# -eq 2 ] || die "usage: tools/fuzz.sh ci SECONDS"
    build
    failed=""
    for t in $targets; do
      t=${t%%:*}
      # New inputs go to a throw-away folder: a CI run leaves the kept corpus as it is.
      mkdir -p "$scratch/new-$t"
      log="$scratch/$t.log"
      # A fixed seed and a bounded number of mutations: the same inputs on every machine, so
      # CI is a regression check of the kept corpus plus a reproducible short exploration
      # (campaigns with `run` explore at random).
      if fuzz "$t" "$2" "$scratch/new-$t" "corpus/$t" -seed=1 -runs=$((4000 * $2)) >"$log" 2>&1; then
        echo "fuzz $t: ok, $(grep -o 'stat::number_of_executed_units: [0-9]*' "$log" | grep -o '[0-9]*$') runs," \
          "$(grep -E '^#[0-9]+.*(DONE|INITED)' "$log" | tail -1 | grep -oE 'cov: [0-9]+ ft: [0-9]+')"
      else
        echo "fuzz $t: FAILED; libFuzzer's output:"
        cat "$log"
        failed="$failed $t"
      fi
    done
    if [ -n "$failed" ]; then
      echo "fuzz: findings in:$failed (inputs in fuzz/artifacts/)"
      exit 1
    fi
    echo "fuzz: every target ran $2 s without a finding"
    ;;
  min)
    [ $# -eq 2 ] || die "usage: tools/fuzz.sh min TARGET"
    t=$2
    max_len "$t" >/dev/null
    build
    # The seeds stay as they are; of the other inputs, a small set that covers every code edge
    # they reach beyond the seeds is kept (edges only: counters and compare operands would
    # keep hundreds of near-copies), under libFuzzer's names (the SHA-1 of the input).
    kept="$scratch/kept"
    mkdir -p "$kept"
    cp corpus/"$t"/seed-* "$kept"/
    "$bin_dir/$t" -set_cover_merge=1 -use_counters=0 -use_cmp=0 -max_len="$(max_len "$t")" $limits "$kept" "corpus/$t"
    find "corpus/$t" -type f ! -name 'seed-*' -delete
    find "$kept" -type f ! -name 'seed-*' -exec mv -t "corpus/$t" {} +
    echo "corpus/$t: $(find "corpus/$t" -type f | wc -l) inputs"
    ;;
  repro)
    [ $# -ge 3 ] || die "usage: tools/fuzz.sh repro TARGET FILE..."
    t=$2
    shift 2
    max_len "$t" >/dev/null
    build
    files=()
    for f in "$@"; do files+=("$(cd "$caller" && realpath "$f")"); done
    "$bin_dir/$t" $limits "${files[@]}"
    ;;
  *)
    awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$script"
    [ -z "$cmd" ] || exit 2
    ;;
esac
