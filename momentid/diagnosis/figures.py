"""The replay figure the added-mass and modal paths share (the twin path draws its own)."""

from __future__ import annotations

from pathlib import Path

from momentid.diagnosis.result import Diagnosis
from momentid.mechanisms.place import location_words

__all__ = ["plot_replay"]


def plot_replay(diag: Diagnosis, path: Path) -> None:
    """``replay.png`` of the added-mass and modal paths: per floor channel, the held-out run recorded, as the
    linear and the augmented model replay it, and what each leaves."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = diag.curves
    t = c["time"]
    g = "q" if "q" in c["measured"] else "a"
    d = c["measured"][g].shape[1]
    fig, axes = plt.subplots(d, 2, figsize=(12, 2.4 * d), squeeze=False, sharex=True)
    unit = "m" if g == "q" else "m/s^2"
    for j in range(d):
        m, lin, aug = c["measured"][g][:, j], c["linear"][g][:, j], c["augmented"][g][:, j]
        ax = axes[j, 0]
        ax.plot(t, m, "k", lw=0.8, label="recorded")
        ax.plot(t, lin, "C0", lw=0.8, label="linear model")
        ax.plot(t, aug, "C3--", lw=0.8, label="augmented model")
        ax.set_ylabel(f"{g}{j + 1} ({unit})")
        ax = axes[j, 1]
        ax.plot(t, m - lin, "C0", lw=0.6, label="residual, linear")
        ax.plot(t, m - aug, "C3", lw=0.6, label="residual, augmented")
        ax.set_ylabel(f"{g}{j + 1} residual ({unit})")
    axes[0, 0].legend(fontsize=7)
    axes[0, 1].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    fig.suptitle(f"{diag.mechanism.replace('_', ' ')} at {location_words(diag.location)}: held-out NRMSE "
                 f"{100 * diag.nrmse_before:.2f} % -> {100 * diag.nrmse_after:.2f} %")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
