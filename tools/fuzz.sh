#!/usr/bin/env bash
# A fuzz campaign of fixed length: every cargo-fuzz target of fuzz/ (or those named), one after the
# other, each for SECONDS on one core, then a summary line per target (executions, coverage, corpus,
# crashes). Exit code 0 when no target crashed, 1 when one did (its input is kept under
# <target dir>/fuzz/artifacts/<target>/), 2 on a usage or setup error.
#
#   tools/fuzz.sh [SECONDS] [TARGET...]        # default: 300 s, every target
#   tools/fuzz.sh 600                          # the campaign of docs/reliability.md: 10 minutes each
#   tools/fuzz.sh 60 json_import               # one target, one minute (a CI smoke run)
#
# Needs the nightly toolchain and cargo-fuzz (`rustup toolchain install nightly`,
# `cargo install cargo-fuzz`). The fuzz build goes to $CARGO_TARGET_DIR/fuzz (default target/fuzz); the
# corpus of each target lives there too and grows from run to run, seeded from data/ (the example
# traces, the goal files' reward programs and rules). Set FUZZ_ARGS for extra libFuzzer flags.
#
# The build is cargo-fuzz's development profile by default: the whole dependency tree (DataFusion, Arrow,
# the physics engines) with coverage instrumentation compiles in about 15 minutes on 2 cores, where the
# optimised build (one codegen unit per crate) takes well over an hour. FUZZ_RELEASE=1 selects the
# optimised build, which runs more inputs per second once built.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
secs=${1:-300}
if ! [[ $secs =~ ^[0-9]+$ ]] || [ "$secs" -lt 1 ]; then
    echo "usage: tools/fuzz.sh [SECONDS] [TARGET...]  (SECONDS a positive whole number, got '$secs')" >&2
    exit 2
fi
shift || true
if [ $# -gt 0 ]; then
    targets=("$@")
else
    mapfile -t targets < <(sed -n 's/^name = "\(.*\)"$/\1/p' "$root/fuzz/Cargo.toml" | grep -v '^annotrace-fuzz$')
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    echo "tools/fuzz.sh: needs cargo-fuzz on the nightly toolchain:" >&2
    echo "  rustup toolchain install nightly && cargo install cargo-fuzz" >&2
    exit 2
fi

out=${CARGO_TARGET_DIR:-$root/target}/fuzz
mkdir -p "$out"

# Seeds: a corpus file per example trace (first byte: environment and layout, as the target reads it)
# and per reward program and verification rule of the goal files.
seed() {
    local target=$1 dir=$2
    mkdir -p "$dir"
    case $target in
        json_import)
            local i=0 env
            for env in pooltool phyre iphyre; do
                local f
                f=$(ls "$root"/data/examples/"$env"_*.json | head -1)
                printf "\\x$(printf %02x $i)" | cat - "$f" > "$dir/seed-$env.json"
                # The same trace as one JSON Lines record (0x80: JSON Lines).
                if command -v python3 >/dev/null; then
                    printf "\\x$(printf %02x $((i | 128)))" > "$dir/seed-$env.jsonl"
                    python3 -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))))' "$f" >> "$dir/seed-$env.jsonl"
                fi
                i=$((i + 1))
            done
            ;;
        reward_dsl)
            if command -v python3 >/dev/null; then
                python3 - "$root/data/goals" "$dir" <<'PY'
import pathlib, sys, tomllib
src, dst = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
for f in sorted(src.glob("*.toml")):
    for g in tomllib.loads(f.read_text()).get("goal", []):
        for key in ("program", "rule", "verify"):
            if isinstance(g.get(key), str):
                (dst / f"seed-{f.stem}-{g['id']}-{key}").write_text(g[key])
PY
            fi
            ;;
    esac
}

profile=(--dev)
[ "${FUZZ_RELEASE:-0}" = 1 ] && profile=()

summary=()
crashed=0
cd "$root"
for t in "${targets[@]}"; do
    corpus="$out/corpus/$t"
    artifacts="$out/artifacts/$t/"
    mkdir -p "$corpus" "$artifacts"
    [ -n "$(ls -A "$corpus")" ] || seed "$t" "$corpus"
    log="$out/$t.log"
    echo "== $t: ${secs} s, corpus $corpus, log $log" >&2
    set +e
    # One process, one job (libFuzzer's default); no sanitizer: annotrace is safe Rust, and the
    # uninstrumented build runs several times more inputs per second.
    # shellcheck disable=SC2086
    cargo +nightly fuzz run "$t" "${profile[@]}" --sanitizer none --target-dir "$out" "$corpus" -- \
        -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
        -artifact_prefix="$artifacts" ${FUZZ_ARGS:-} 2>&1 | tee "$log" | grep -E '^(#[0-9]+.*(pulse|DONE)|==|Running|artifact_prefix|SUMMARY|thread .* panicked)' >&2
    rc=${PIPESTATUS[0]}
    set -e
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    last=$(grep -E '^#[0-9]+' "$log" | tail -1 || true)
    cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
    ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
    corp=$(sed -n 's/.* corp: \([0-9]*\/[0-9]*[a-zA-Z]*\).*/\1/p' <<<"$last")
    found=$(find "$artifacts" -type f | wc -l)
    if [ "$rc" -ne 0 ] || [ "$found" -gt 0 ]; then
        crashed=1
    fi
    summary+=("$(printf '%-12s %5s s  execs %-10s exec/s %-7s cov %-6s ft %-7s corpus %-12s crashes %s  (exit %s)' \
        "$t" "$secs" "${execs:-?}" "${speed:-?}" "${cov:-?}" "${ft:-?}" "${corp:-?}" "$found" "$rc")")
done

echo
printf '%s\n' "${summary[@]}"
if [ "$crashed" -ne 0 ]; then
    echo "a target crashed: inputs under $out/artifacts/ (replay with: cargo +nightly fuzz run TARGET ${profile[*]} --sanitizer none --target-dir $out FILE)" >&2
    exit 1
fi
