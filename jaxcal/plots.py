"""Matplotlib figures (Agg backend: files only, no display needed)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import textwrap  # noqa: E402

STYLE = {"nominal": dict(color="0.4", marker="o"), "linear": dict(color="tab:orange", marker="s"),
         "gn": dict(color="tab:blue", marker="^"), "lm": dict(color="tab:cyan", marker="v"),
         "elimination": dict(color="tab:green", marker="D"),
         "elimination-literal": dict(color="tab:red", marker="x")}
LABEL = {"nominal": "nominal model", "linear": "one-shot least squares", "gn": "Gauss–Newton",
         "lm": "Levenberg–Marquardt", "elimination": "elimination (robust)",
         "elimination-literal": "elimination (literal, paper)"}


def axis_deviation(path, axis: str, deviations: dict, *, title: str) -> None:
    """Per-pose deviation of the end position along ``axis`` (paper Figs. 3-5): one panel with
    every model, one zoomed on the calibrated models (their errors are orders smaller)."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    limit = 10.0 * max(float(np.abs(deviations.get("nominal", np.ones(1))).max()), 1e-9)
    notes = []
    for name, dev in deviations.items():
        idx = np.arange(1, len(dev) + 1)
        worst = float(np.nanmax(np.abs(dev))) if np.isfinite(dev).any() else float("inf")
        if not np.isfinite(worst) or worst > limit:  # a diverged model: say so instead of plotting
            notes.append(f"{LABEL.get(name, name)}: off scale (max |deviation| = {worst:.3g} mm)")
            continue
        kw = dict(STYLE.get(name, {}), markersize=4, linewidth=1)
        top.plot(idx, dev, label=LABEL.get(name, name), **kw)
        if name != "nominal":
            bottom.plot(idx, dev, label=LABEL.get(name, name), **kw)
    top.set_ylabel(f"{axis} deviation (mm)")
    top.set_title(title, fontsize=10)
    if notes:
        top.text(0.01, 0.02, "\n".join(notes), transform=top.transAxes, fontsize=8, color="tab:red",
                 va="bottom")
    top.legend(fontsize=8, ncol=2)
    top.grid(alpha=0.3)
    bottom.set_ylabel(f"{axis} deviation (mm)\ncalibrated models only")
    bottom.set_xlabel("inspection pose number (not used in calibration)")
    bottom.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3))
    bottom.legend(fontsize=8, ncol=2)
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def timing(path, runs_ms: dict, compile_s: dict, *, title: str) -> None:
    """Distribution of calibration times per method (paper Fig. 6) and compile times apart."""
    names = list(runs_ms)
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2), gridspec_kw={"width_ratios": [3, 2]})
    data = [runs_ms[n] for n in names]
    left.boxplot(data, showfliers=True)
    rng = np.random.default_rng(0)
    for i, d in enumerate(data, start=1):
        left.scatter(i + rng.uniform(-0.12, 0.12, len(d)), d, s=8, alpha=0.5,
                     color=STYLE.get(names[i - 1], {}).get("color", "k"))
    ticks = [textwrap.fill(LABEL.get(n, n), 14) for n in names]
    left.set_xticks(range(1, len(names) + 1), ticks, fontsize=8)
    left.set_ylabel("calibration time after compilation (ms)")
    left.set_yscale("log")
    left.set_title(title, fontsize=10)
    left.grid(alpha=0.3, axis="y")
    right.bar(range(len(names)), [compile_s[n] for n in names],
              color=[STYLE.get(n, {}).get("color", "k") for n in names])
    right.set_xticks(range(len(names)), ticks, fontsize=8)
    right.set_ylabel("compile time, once per shape (s)")
    right.set_title("JIT compilation (not in the left panel)", fontsize=10)
    right.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
