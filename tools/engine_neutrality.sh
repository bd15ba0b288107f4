#!/usr/bin/env bash
# Reads every table of a run folder with three other engines — DuckDB, polars and pyarrow — and checks
# each table's row count and columns (names in order, and types up to each engine's spelling) against
# `annotrace tables`: the proof that a run's tables are plain Parquet any engine reads, not annotrace's.
#
# Like annotrace, the engines read only the files the manifest publishes (the outputs of finished
# stages, plus the `llm_calls` journal folder), never a folder listing, and take the `env=` folder
# of a partitioned table as its `env` column (hive partitioning).
#
#   tools/engine_neutrality.sh runs/quickstart            # exit 0 when every engine agrees, 1 otherwise
#
# The engines live in a venv the script creates on first use (pip install duckdb polars pyarrow):
# ANNOTRACE_ENGINES_VENV (default ~/.cache/annotrace-engines-venv). ANNOTRACE_BIN names the annotrace
# binary (default: `annotrace` on the PATH, else target/debug/annotrace).
set -euo pipefail
run="${1:?usage: tools/engine_neutrality.sh RUN_DIR}"
venv="${ANNOTRACE_ENGINES_VENV:-$HOME/.cache/annotrace-engines-venv}"
here="$(cd "$(dirname "$0")/.." && pwd)"
bin="${ANNOTRACE_BIN:-}"
if [[ -z "$bin" ]]; then
  if command -v annotrace >/dev/null; then bin=annotrace; else bin="$here/target/debug/annotrace"; fi
fi
if [[ ! -x "$venv/bin/python" ]]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet duckdb polars pyarrow
fi
tables="$(mktemp)"
trap 'rm -f "$tables"' EXIT
"$bin" tables --run "$run" > "$tables"
"$venv/bin/python" - "$run" "$tables" <<'PY'
import json, os, re, sys
from collections import defaultdict

import duckdb
import polars as pl
import pyarrow as pa
import pyarrow.dataset as ds

run, tables_txt = sys.argv[1], sys.argv[2]

# annotrace's view: "name: N rows in K file(s)" then "  column  Type[ not null]".
expected = {}
current = None
for line in open(tables_txt):
    m = re.match(r"^(\S+): (\d+) rows in (\d+) file\(s\)$", line.rstrip("\n"))
    if m:
        current = m.group(1)
        expected[current] = {"rows": int(m.group(2)), "columns": []}
        continue
    m = re.match(r"^  (\S+)\s+(.+?)( not null)?$", line.rstrip("\n"))
    if m and current:
        expected[current]["columns"].append((m.group(1), m.group(2)))

# The published files, as annotrace lists them.
manifest = json.load(open(os.path.join(run, "manifest.json")))
files = defaultdict(list)
for stage in manifest["stages"].values():
    if stage["status"] != "finished":
        continue
    for o in stage["outputs"]:
        path = o["path"] if isinstance(o, dict) else o
        parts = path.split("/")
        if (len(parts) in (2, 3) and path.endswith(".parquet") and not parts[0].startswith((".", "_"))
                and parts[0] != "exports" and not parts[-1].startswith(".")):
            files[parts[0]].append(os.path.join(run, path))
journal = os.path.join(run, "llm_calls")
if os.path.isdir(journal):
    files["llm_calls"] += sorted(os.path.join(journal, f) for f in os.listdir(journal)
                                 if f.endswith(".parquet") and not f.startswith("."))


def kind(t):
    """A type's family, the same whichever engine spells it: string, int32, float64, list<string>, …"""
    t = str(t).lower()
    t = re.sub(r"^dictionary\((int\d+|uint\d+), *(.+)\)$", r"\2", t)   # annotrace (DataFusion)
    t = re.sub(r"^dictionary<values=(.+), indices=.*>$", r"\1", t)     # pyarrow
    t = re.sub(r"^categorical.*$", "string", t)                         # polars
    for a, b in [("utf8view", "string"), ("large_utf8", "string"), ("large_string", "string"),
                 ("largeutf8", "string"), ("utf8", "string"), ("varchar", "string"), ("str", "string"),
                 ("string_view", "string"),
                 ("bigint", "int64"), ("integer", "int32"), ("int64", "int64"), ("int32", "int32"),
                 ("i64", "int64"), ("i32", "int32"), ("double", "float64"), ("f64", "float64"),
                 ("float64", "float64"), ("boolean", "bool"), ("bool", "bool")]:
        if t == a:
            return b
    m = re.match(r"^(list|large_list)\((?:field \S+ )?(.+?)\)$|^list<(?:item: )?(.+)>$|^(.+)\[\]$", t)
    if m:
        inner = next(g for g in m.groups()[1:] if g)
        inner = re.sub(r"^field\s*\{.*data_type:\s*(\w+).*\}$", r"\1", inner)
        return "list<" + kind(inner) + ">"
    return t


def engines(paths, partitioned):
    hive = "hive" if partitioned else None
    base = os.path.commonpath([os.path.dirname(os.path.dirname(p)) if partitioned else os.path.dirname(p)
                               for p in paths])
    d = ds.dataset(paths, format="parquet", partitioning=hive, partition_base_dir=base)
    t = d.to_table()
    yield "pyarrow", t.num_rows, [(f.name, kind(f.type)) for f in t.schema]
    con = duckdb.connect()
    rel = con.read_parquet(paths, hive_partitioning=partitioned)
    n = con.execute("SELECT count(*) FROM rel").fetchone()[0]
    yield "duckdb", n, [(c, kind(ty)) for c, ty in zip(rel.columns, rel.types)]
    lf = pl.scan_parquet(paths, hive_partitioning=partitioned)
    schema = lf.collect_schema()
    n = lf.select(pl.len()).collect().item()
    yield "polars", n, [(c, kind(ty)) for c, ty in schema.items()]


failures = 0
checked = 0
for name, want in sorted(expected.items()):
    paths = sorted(files.get(name, []))
    if not paths:
        if want["rows"]:
            print(f"{name}: annotrace counts {want['rows']} rows but the manifest publishes no file")
            failures += 1
        continue
    partitioned = any("/env=" in p for p in paths)
    want_cols = [(c, kind(t)) for c, t in want["columns"]]
    before = failures
    for engine, rows, cols in engines(paths, partitioned):
        checked += 1
        problems = []
        if rows != want["rows"]:
            problems.append(f"{rows} rows, annotrace {want['rows']}")
        # Column order: the partition column may come first or last; compare by name, then types.
        if sorted(c for c, _ in cols) != sorted(c for c, _ in want_cols):
            problems.append(f"columns {[c for c, _ in cols]}, annotrace {[c for c, _ in want_cols]}")
        else:
            theirs = dict(cols)
            for c, t in want_cols:
                if theirs[c] != t:
                    problems.append(f"column {c}: {theirs[c]}, annotrace {t}")
        if problems:
            failures += 1
            print(f"{name} [{engine}]: " + "; ".join(problems))
    if failures == before:
        print(f"{name}: {want['rows']} rows, {len(want_cols)} columns: pyarrow, duckdb and polars agree")
print(f"{len(expected)} table(s), {checked} engine reads, {failures} disagreement(s)")
sys.exit(1 if failures else 0)
PY
