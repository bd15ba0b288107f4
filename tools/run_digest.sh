#!/usr/bin/env bash
# Prints the SHA-256 of every table file and export of a run folder, one line per file, sorted by path:
# the proof that a refactor left a pipeline's outputs byte-identical. Left out: manifest.json (times and
# durations), the lock file and hidden folders (.staging, LLM call logs under dot-folders).
#
#   tools/run_digest.sh runs/quickstart > before.sha256
#   ... change the code, rerun the pipeline into a fresh run folder ...
#   tools/run_digest.sh runs/quickstart | diff before.sha256 -
set -euo pipefail
run="${1:?usage: tools/run_digest.sh RUN_DIR}"
cd "$run"
find . -type f ! -path './.*' ! -name manifest.json ! -name '*.lock' -print0 \
  | sort -z \
  | xargs -0 sha256sum
