#!/usr/bin/env python3
"""The side-by-side table of tools/side_by_side.sh.

  side_by_side_table.py WORK SCALE            prints the Markdown section from the measurements in WORK
  side_by_side_table.py --into DOC TABLE.md   replaces the section between the side-by-side markers of DOC
"""
import json
import re
import sys
from pathlib import Path

BEGIN = "<!-- side-by-side:begin (tools/side_by_side.sh writes this section) -->"
END = "<!-- side-by-side:end -->"


def originals(work: Path) -> dict:
    pool = json.loads((work / "pooltool.json").read_text())
    sim = pool["random_shots_default_engine"]
    cont = pool["continuize_dt_0.0100"]
    out = {
        "pool_sim": sim["shots_per_s"],
        "pool_sim_cont": 1000.0 / (sim["mean_ms_per_shot"] + cont["mean_ms_per_shot"]),
        "pool_n": sim["n_shots"],
    }
    for line in (work / "phyre.log").read_text().splitlines():
        m = re.match(r"simulate_action \[(.*)\]: ([0-9.]+) episodes/s", line)
        if m:
            out["phyre " + m.group(1)] = float(m.group(2))
        m = re.match(r"steps \[(.*)\]: ([0-9.]+) per episode", line)
        if m:
            out["phyre steps " + m.group(1)] = float(m.group(2))
        m = re.match(r"outcomes agreeing with annotrace: (\d+) of (\d+)", line)
        if m:
            out["phyre agree"] = (int(m.group(1)), int(m.group(2)))
    for line in (work / "iphyre.log").read_text().splitlines():
        m = re.match(r"(simulate60|recorder60) ([0-9.]+) episodes/s over (\d+)", line)
        if m:
            out["iphyre " + m.group(1)] = float(m.group(2))
            out["iphyre " + m.group(1) + " n"] = int(m.group(3))
    return out


def fmt(x: float) -> str:
    return f"{x:,.0f}" if x >= 100 else f"{x:,.1f}"


def table(work: Path, scale: str) -> str:
    o = originals(work)
    rows = [json.loads(l) for l in (work / "annotrace.jsonl").read_text().splitlines() if l.strip()]
    by = {(r["case"], r["threads"]): r for r in rows}
    env = dict(l.split("=", 1) for l in (work / "env.txt").read_text().splitlines() if "=" in l)
    profile = env.get("build") or (rows[0]["profile"] if rows else "?")
    if profile == "dist":
        profile = ("**dist build** (release with LTO across crates and one codegen unit: "
                   "`cargo build --profile dist`)")
    else:
        profile = f"**{profile} build**"
    lines = [
        BEGIN,
        "",
        f"Measured by `SCALE={scale} tools/side_by_side.sh` on {env.get('date')}: {env.get('machine')}; "
        f"load average at the end {env.get('load')}. {env.get('annotrace')}, {profile}; "
        f"pooltool {env.get('pooltool')}; PHYRE {env.get('phyre')}; I-PHYRE {env.get('iphyre')}. "
        "annotrace figures are `annotrace bench` (the `simulate` command as a child process, into "
        "Parquet, wall time of the process); the originals' are their own speed scripts in the same "
        "session, single-threaded, timed by wall clock inside the process (perf_counter), so the "
        "ratio compares wall with wall; annotrace's CPU-time rate is given beside it because the "
        "machine is shared.",
        "",
        "| environment | annotrace, 1 thread | 2 threads | frame rows/s (1 thread) | Parquet per 1,000 traces | original, same session | ratio | goal |",
        "|---|---:|---:|---:|---:|---|---:|---|",
    ]

    def row(case, label, unit, orig_label, orig, goal_text, goal_ok):
        one, two = by.get((case, 1)), by.get((case, 2))
        if not one:
            return
        speed2 = f"{fmt(two['items_per_s'])} ({two['items_per_s'] / one['items_per_s']:.2f}×)" if two else "—"
        ratio = one["items_per_s"] / orig if orig else float("nan")
        met = "met" if goal_ok(one, ratio) else "**not met**"
        lines.append(
            f"| {label} ({one['items']} {unit}, {one['frame_rows'] / 1e6:.2f} M frame rows) "
            f"| {fmt(one['items_per_s'])} {unit}/s (per CPU s: {fmt(one['items_per_cpu_s'])}) | {speed2} | {one['frame_rows_per_s'] / 1e6:.2f} M (per CPU s: {one['frame_rows'] / max(one['cpu_s'], 1e-9) / 1e6:.2f} M) "
            f"| {one['parquet_bytes_per_1000_traces'] / 1e6:.1f} MB | {orig_label} {fmt(orig)} /s "
            f"| {ratio:.2f}× | {goal_text}: {met} |"
        )

    row("pool", "billiards, 1 shot per rack, dt 0.01", "shots",
        f"pooltool `simulate` + `continuize` ({o['pool_n']} shots; `simulate` alone {fmt(o['pool_sim'])} /s)",
        o["pool_sim_cont"], "≥ 1,000 shots/s and ≥ 80×",
        lambda r, x: r["items_per_s"] >= 1000 and x >= 80)
    row("phyre-1", "PHYRE, every step", "episodes", "PHYRE featurised objects stride 1",
        o.get("phyre featurized objects stride 1", 0), "≥ 2×", lambda r, x: x >= 2)
    row("phyre-6", "PHYRE, stride 6", "episodes", "PHYRE status only",
        o.get("phyre status only", 0), "≥ 1×", lambda r, x: x >= 1)
    row("iphyre", "I-PHYRE 60 fps, 40 games", "episodes",
        f"iphyre `simulate()` without recording ({o.get('iphyre simulate60 n')} episodes; its trace recorder "
        f"{fmt(o.get('iphyre recorder60', 0))} /s)",
        o.get("iphyre simulate60", 0), "≥ 1×", lambda r, x: x >= 1)
    ours_status = o.get("phyre status only, annotrace episodes")
    ours_feat = o.get("phyre featurized objects stride 1, annotrace episodes")
    if ours_status and ours_feat and (("phyre-6", 1) in by or ("phyre-1", 1) in by):
        ratios = []
        if ("phyre-1", 1) in by:
            ratios.append(f"every step {by[('phyre-1', 1)]['items_per_s'] / ours_feat:.2f}× its featurised "
                          f"stride 1 ({fmt(ours_feat)} /s)")
        if ("phyre-6", 1) in by:
            ratios.append(f"stride 6 {by[('phyre-6', 1)]['items_per_s'] / ours_status:.2f}× its status only "
                          f"({fmt(ours_status)} /s)")
        agree = o.get("phyre agree")
        lines += [
            "",
            "**The same PHYRE episodes on both sides.** The original's rates above are over its own random "
            "valid actions on the ball tier's first within-template test tasks; run instead on annotrace's "
            "own episodes (the tasks and actions of the PHYRE cases above), PHYRE gives "
            + "; ".join(ratios)
            + f". Steps simulated per episode: {o.get('phyre steps own set', float('nan')):.1f} in the "
            f"original's set, {o.get('phyre steps annotrace episodes', float('nan')):.1f} in annotrace's"
            + (f"; the original's outcome (solved or not) agrees with annotrace's on {agree[0]} of "
               f"{agree[1]} episodes." if agree else "."),
        ]
    lines += [
        "",
        "Two threads against one: "
        + ", ".join(
            f"{c} {by[(c, 2)]['items_per_s'] / by[(c, 1)]['items_per_s']:.2f}×"
            for c in ("pool", "phyre-1", "phyre-6", "iphyre")
            if (c, 1) in by and (c, 2) in by
        )
        + " (goal ≥ 1.8×).",
    ]
    ann = [by[("annotate", w)] for w in (1, 2) if ("annotate", w) in by]
    if ann:
        last = ann[-1]
        met = "met" if last["threads"] == 2 and last["wall_ms_per_item"] <= 3.0 else "**not met**"
        lines += [
            "",
            f"**Annotation** (`annotrace bench`'s `annotate` case: `annotrace annotate --env pooltool "
            f"--workers <n>`, the 12 built-in detectors over the pool case's {last['traces']} shots, each "
            "run on its own copy of them; CPU includes the detector workers): "
            + "; ".join(
                f"{r['threads']} worker{'s' if r['threads'] > 1 else ''} {r['wall_ms_per_item']:.2f} ms "
                f"per trace of wall, {1000 * r['cpu_s'] / max(r['items'], 1):.2f} ms of CPU"
                for r in ann
            )
            + f" (goal ≤ 3 ms per trace on 2 workers: {met}).",
        ]
    lines += [
        "",
        END,
    ]
    return "\n".join(lines) + "\n"


def into(doc: Path, section: Path) -> None:
    text = doc.read_text()
    new = section.read_text().rstrip("\n")
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        text = head + new + tail
    else:
        text = text.rstrip("\n") + "\n\n## Side by side with the originals\n\n" + new + "\n"
    doc.write_text(text)


if __name__ == "__main__":
    if sys.argv[1] == "--into":
        into(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        sys.stdout.write(table(Path(sys.argv[1]), sys.argv[2]))
