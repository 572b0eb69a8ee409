"""How large the report pages and UFF files are for the shipped rigs and a simulated diagnosis.

    python -m benchmarks.report_sizes [--keep DIR]

Imports both shipped rigs (``data/mini_shake_table/flexible_3storey`` and ``stiff_1storey``) and
simulates ``scenarios/hidden/damper_storey3.toml``, then runs the commands that write a
``report.html``: ``identify -o``, ``identify --per-run -o``, ``twin -o`` and ``diagnose -o``, each with
its default trials (every trial; the twin leaves out one the rig-state check sets apart).  Records each page's
size, its figures, and the UFF files' sizes; a command that refuses is recorded with its one-line error.  Writes
``benchmarks/results/report_sizes.json`` and ``report_sizes.md``.
"""

from __future__ import annotations

import argparse
import re
import tempfile
from pathlib import Path

from benchmarks.common import RESULTS, ROOT, machine, save
from benchmarks.twin import cli, timed

DATA = ROOT / "data" / "mini_shake_table"


def commands(rec: Path, out: Path) -> list:
    """``(label, argv, folder)`` of every command that writes a report."""
    return [("identify -o", ["identify", str(rec), "-o", str(out / "id")], out / "id"),
            ("identify --per-run -o", ["identify", str(rec), "--per-run", "-o", str(out / "per_run")],
             out / "per_run"),
            ("twin -o", ["twin", str(rec), "-o", str(out / "twin")], out / "twin"),
            ("diagnose -o", ["diagnose", str(rec), "-o", str(out / "diag")], out / "diag")]


def measure(folder: Path) -> dict:
    page = (folder / "report.html").read_text(encoding="utf-8")
    sizes = {p.name: p.stat().st_size for p in sorted(folder.iterdir()) if p.suffix in (".html", ".uff")}
    return {"files_bytes": sizes, "figures": page.count('<figure id="figure-'),
            "missing": page.count('class="figure-missing"')}


def run(work: Path) -> list:
    rows = []
    sources = [(rig, ["import", str(DATA / rig), "-o", str(work / f"{rig}.mcap")], work / f"{rig}.mcap")
               for rig in ("flexible_3storey", "stiff_1storey")]
    sources.append(("damper_storey3 (simulated)",
                    ["run", str(ROOT / "scenarios" / "hidden" / "damper_storey3.toml"), "-o", str(work), "-q"],
                    work / "damper_storey3.mcap"))
    for rig, make, rec in sources:
        assert cli(make) is None, f"{rig}: {make}"
        for label, argv, folder in commands(rec, work / rig.split(" ")[0]):
            if rig.endswith("(simulated)") and label != "diagnose -o":
                continue
            error, wall, _ = timed(lambda: cli(argv))
            row = {"rig": rig, "command": label, "seconds": round(wall, 1), "error": error}
            if error is None:
                row.update(measure(folder))
            rows.append(row)
            print(row)
    return rows


def markdown(rows: list) -> list:
    lines = ["# Report sizes", "", "`python -m benchmarks.report_sizes`: each command's `report.html` (and `identify "
             "-o`'s UFF files), in kB (1000 bytes); the command's wall seconds are in `report_sizes.json`.", "",
             "| rig | command | report.html (kB) | figures | modes.uff (kB) | frf.uff (kB) |",
             "|---|---|---:|---:|---:|---:|"]
    for r in rows:
        if r["error"]:
            reason = re.sub(r"^\S+\.mcap: ", "", r["error"].removeprefix("error: ")).split(": expected")[0]
            lines.append(f"| {r['rig']} | `{r['command']}` | refused: {reason} | | | |")
            continue
        kb = {name: f"{size / 1000:.0f}" for name, size in r["files_bytes"].items()}
        lines.append(f"| {r['rig']} | `{r['command']}` | {kb['report.html']} | {r['figures']} | "
                     f"{kb.get('modes.uff', '')} | {kb.get('frf.uff', '')} |")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.report_sizes", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--keep", metavar="DIR", help="write the reports into DIR (kept) instead of a temporary folder")
    args = p.parse_args(argv)
    if args.keep:
        Path(args.keep).mkdir(parents=True, exist_ok=True)
        rows = run(Path(args.keep))
    else:
        with tempfile.TemporaryDirectory() as tmp:
            rows = run(Path(tmp))
    save(RESULTS, "report_sizes", {"machine": machine(), "rows": rows}, markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
