"""Windows of every shipped real trial, cut anywhere: each damping agrees with its whole trial's, or is refused.

    python -m benchmarks.real_windows [--rig stiff_1storey|flexible_3storey|both] [--out DIR]

A real monitoring record seldom starts at rest.  Every trial of both shipped rigs (``data/mini_shake_table``)
is cut into windows (the stiff 1-storey: 15 s every 3 s; the flexible 3-storey: 20 s every 10 s), each
window identified on its own as ``momentid identify`` does (its noise level from its own data, most often
its own scatter), and each storey mode's damping at small amplitude compared with the whole trial's:
the two agree when they differ by at most two standard errors of their difference (a 95 % check).  A
window's answer against a refused whole trial is counted apart.  Issue 29 point 4 asks that every window
agree or refuse; the table lists each window that does neither.

Writes ``benchmarks/results/real_windows.md`` and ``real_windows.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

from benchmarks.common import RESULTS, ROOT

#: Per rig: window length (s) and the step between window starts (s).
WINDOWS = {"stiff_1storey": (15.0, 3.0), "flexible_3storey": (20.0, 10.0)}
#: Two answers agree within this many standard errors of their difference.
AGREE_SIGMAS = 2.0


def windows(run, length: float, step: float) -> list:
    """``(start (s), RunData)`` of the windows of ``run``; the last may be shorter (at least half a window)."""
    fs, n = run.sample_rate, int(length * run.sample_rate)
    return [(a / fs, run.window(a, a + n)) for a in range(0, run.n_samples - n // 2, int(step * fs))]


def judge(window, whole) -> str:
    """``refused``, ``agrees``, ``disagrees`` or ``trial refused`` for one mode's damping answer."""
    if not window.is_answer:
        return "refused"
    if not whole.is_answer:
        return "trial refused"
    gap = abs(window.damping_ratio - whole.damping_ratio)
    allowed = AGREE_SIGMAS * np.hypot(window.damping_ratio_std, whole.damping_ratio_std)
    return "agrees" if gap <= allowed else "disagrees"


def evaluate(rig: str) -> list[dict]:
    """Every window of every trial of ``rig``: one row per storey mode."""
    import momentid as mi
    from momentid.errors import MomentidError
    from momentid.estimation.scaled import identify_per_run

    experiment = mi.import_folder(ROOT / "data" / "mini_shake_table" / rig)
    whole = dict(zip([r.name for r in experiment.runs], identify_per_run(experiment)))
    length, step = WINDOWS[rig]
    rows = []
    for run in experiment.runs:
        for start, window in windows(run, length, step):
            try:
                r = mi.identify(dataclasses.replace(experiment, runs=(window,)))
            except MomentidError as exc:
                rows.append({"rig": rig, "trial": run.name, "start_s": start, "mode": None, "verdict": "refused",
                             "why": str(exc)})
                continue
            for i, (w, t) in enumerate(zip(r.damping, whole[run.name].damping)):
                rows.append({"rig": rig, "trial": run.name, "start_s": start, "mode": i + 1, "verdict": judge(w, t),
                             "window": w.to_dict(), "trial_damping": t.to_dict(), "noise": r.noise[0],
                             "why": w.refusal})
    return rows


def table(rows: list[dict]) -> str:
    """The counts per rig and every window that disagrees."""
    lines = ["| rig | window modes | refused | agree | answered where the trial refuses | disagree |",
             "|---|---|---|---|---|---|"]
    for rig in dict.fromkeys(r["rig"] for r in rows):
        mine = [r for r in rows if r["rig"] == rig]
        count = {v: sum(r["verdict"] == v for r in mine) for v in ("refused", "agrees", "trial refused", "disagrees")}
        lines.append(f"| {rig} | {len(mine)} | {count['refused']} | {count['agrees']} | {count['trial refused']} | "
                     f"{count['disagrees']} |")
    bad = [r for r in rows if r["verdict"] == "disagrees"]
    if bad:
        lines += ["", "| rig | trial | window start (s) | mode | window (%) | from | trial (%) | from |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in bad:
            w, t = r["window"], r["trial_damping"]
            lines.append(f"| {r['rig']} | {r['trial']} | {r['start_s']:.1f} | {r['mode']} | "
                         f"{100 * w['damping_ratio']:.3f} +- {100 * w['damping_ratio_std']:.3f} | {w['source']} | "
                         f"{100 * t['damping_ratio']:.3f} +- {100 * t['damping_ratio_std']:.3f} | {t['source']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    """Run the windows of the chosen rig(s); print and write the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rig", choices=(*WINDOWS, "both"), default="both")
    p.add_argument("--out", type=Path, default=RESULTS, help="results folder (default: benchmarks/results)")
    args = p.parse_args(argv)
    rows = [row for rig in (WINDOWS if args.rig == "both" else (args.rig,)) for row in evaluate(rig)]
    text = table(rows)
    print(text)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "real_windows.md").write_text(
        f"`python -m benchmarks.real_windows --rig {args.rig}` (see its docstring)\n\n{text}\n")
    (args.out / "real_windows.json").write_text(json.dumps(rows, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
