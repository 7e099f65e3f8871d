"""Matplotlib figures of the paper's reproduction and of a data calibration (Agg backend: files
only, no display needed)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import textwrap  # noqa: E402
from pathlib import Path  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._io import write_figure  # noqa: E402

STYLE = {
    "nominal": dict(color="0.4", marker="o"),
    "linear": dict(color="tab:orange", marker="s"),
    "gn": dict(color="tab:blue", marker="^"),
    "lm": dict(color="tab:cyan", marker="v"),
    "elimination": dict(color="tab:green", marker="D"),
    "elimination-literal": dict(color="tab:red", marker="x"),
}
LABEL = {
    "nominal": "nominal model",
    "linear": "one-shot least squares",
    "gn": "Gauss–Newton",
    "lm": "Levenberg–Marquardt",
    "elimination": "elimination (robust)",
    "elimination-literal": "elimination (literal, paper)",
}


def axis_deviation(path, axis: str, deviations: dict, *, title: str, not_converged=()) -> None:
    """Per-pose deviation of the end position along ``axis`` (paper Figs. 3-5): one panel with
    every model, one zoomed on the calibrated models (their errors are orders smaller). The
    models in ``not_converged`` are labelled so; one with no finite deviation is named, not drawn."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    limit = 10.0 * max(float(np.abs(deviations.get("nominal", np.ones(1))).max()), 1e-9)
    notes = []
    for name, dev in deviations.items():
        idx = np.arange(1, len(dev) + 1)
        label = LABEL.get(name, name) + (" (NOT converged)" if name in not_converged else "")
        if not np.isfinite(dev).any():
            notes.append(f"{label}: no estimate (the solver gave non-finite values)")
            continue
        worst = float(np.nanmax(np.abs(dev)))
        if worst > limit:  # a diverged model: say so instead of plotting
            notes.append(f"{label}: off scale (max |deviation| = {worst:.3g} mm)")
            continue
        kw = dict(STYLE.get(name, {}), markersize=4, linewidth=1)
        top.plot(idx, dev, label=label, **kw)
        if name != "nominal":
            bottom.plot(idx, dev, label=label, **kw)
    top.set_ylabel(f"{axis} deviation (mm)")
    top.set_title(title, fontsize=10)
    if notes:
        top.text(0.01, 0.02, "\n".join(notes), transform=top.transAxes, fontsize=8, color="tab:red", va="bottom")
    top.legend(fontsize=8, ncol=2)
    top.grid(alpha=0.3)
    bottom.set_ylabel(f"{axis} deviation (mm)\ncalibrated models only")
    bottom.set_xlabel("inspection pose number (not used in calibration)")
    bottom.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3))
    bottom.legend(fontsize=8, ncol=2)
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    write_figure(fig, path, dpi=120)
    plt.close(fig)


def timing(path, runs_ms: dict, compile_s: dict, *, title: str) -> None:
    """Distribution of calibration times per method (paper Fig. 6) and compile times apart."""
    names = list(runs_ms)
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2), gridspec_kw={"width_ratios": [3, 2]})
    data = [runs_ms[n] for n in names]
    left.boxplot(data, showfliers=True)
    rng = np.random.default_rng(0)
    for i, d in enumerate(data, start=1):
        left.scatter(
            i + rng.uniform(-0.12, 0.12, len(d)), d, s=8, alpha=0.5, color=STYLE.get(names[i - 1], {}).get("color", "k")
        )
    ticks = [textwrap.fill(LABEL.get(n, n), 14) for n in names]
    left.set_xticks(range(1, len(names) + 1), ticks, fontsize=8)
    left.set_ylabel("calibration time after compilation (ms)")
    left.set_yscale("log")
    left.set_title(title, fontsize=10)
    left.grid(alpha=0.3, axis="y")
    right.bar(
        range(len(names)), [compile_s[n] for n in names], color=[STYLE.get(n, {}).get("color", "k") for n in names]
    )
    right.set_xticks(range(len(names)), ticks, fontsize=8)
    right.set_ylabel("compile time, once per shape (s)")
    right.set_title("JIT compilation (not in the left panel)", fontsize=10)
    right.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    write_figure(fig, path, dpi=120)
    plt.close(fig)


def heldout_errors(result):
    """Held-out and frames-only held-out position error per pose (mm; the RMS over the points a
    pose saw)."""
    pp = result.per_pose
    ho, fo = np.asarray(pp["heldout"]), np.asarray(pp["frames_only_heldout"])
    if ho.ndim == 2:  # several points per pose: the RMS over the points seen
        ho, fo = np.sqrt(np.nanmean(ho**2, -1)), np.sqrt(np.nanmean(fo**2, -1))
    return ho, fo


def pose_errors_figure(result):
    """Held-out position error per pose, frames only vs calibrated, the outlier poses marked (a
    :class:`DataCalibration`)."""
    rep, pp = result.report, result.per_pose
    ho, fo = heldout_errors(result)
    fig, ax = plt.subplots(figsize=(10, 4))
    x = np.asarray(pp.get("rows", np.arange(1, len(ho) + 1)), float)  # the file's data rows, as the report names them
    ax.bar(
        x - 0.2, fo, width=0.4, color="tab:gray", label=f"frames only (RMS {rep['frames_only_heldout_rms_mm']:.2f} mm)"
    )
    ax.bar(
        x + 0.2,
        ho,
        width=0.4,
        color="tab:blue",
        label=f"calibrated, {rep['choice']} (RMS {rep['heldout_rms_mm']:.2f} mm)",
    )
    flagged = np.asarray(pp.get("outlier", np.zeros(len(x), bool)), bool)
    scored = np.asarray(pp.get("scored", ~flagged), bool)
    left = rep["outlier_detection"]["excluded"]
    for bad, how, colour in (
        (np.flatnonzero(flagged & ~scored), "left out of the fit and the RMS", "tab:red"),
        (
            np.flatnonzero(flagged & scored),
            "left out of the fit, in the RMS: a region" if left else "kept",
            "tab:orange",
        ),
    ):
        if bad.size:
            ax.scatter(
                x[bad],
                np.maximum(ho, fo)[bad] * 1.05,
                marker="v",
                color=colour,
                zorder=3,
                label=f"outlier ({how}): row{'s' if bad.size > 1 else ''} "
                + ", ".join(str(int(r)) for r in np.asarray(pp["rows"])[bad][:8])
                + (", ..." if bad.size > 8 else ""),
            )
    ax.set_xlabel("pose (CSV data row)")
    ax.set_ylabel("held-out position error (mm)")
    ax.set_title(f"{rep['folds']}-fold cross-validation: error on poses not used for fitting")
    # below the axes: inside, it covers the tallest bars and their markers ("best" also searches
    # every bar: slow, and warns, for a file of thousands of poses)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, fontsize=8)
    fig.tight_layout()
    return fig


def parameter_kind(robot) -> str:
    """What a robot's kinematic parameters are called: a URDF's are its joint frames'."""
    return "joint-frame" if robot.convention == "joint" else "DH"


def parameters_figure(result):
    """Estimated DH (or joint-frame) errors with 1-sigma error bars (a :class:`DataCalibration`)."""
    rep = result.report
    held = rep.get("not_estimated", {})  # an offset a compliance moved is not an estimate
    dh = [
        (k, v)
        for k, v in result.deltas.items()
        if not k.startswith(("base_", "tool_", "point", "camera_")) and k not in held
    ]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, unit, scale, label in (
        (axes[0], "mm", 1.0, "length error (mm)"),
        (axes[1], "rad", 1e3, "angle error (mrad)"),
    ):
        sel = [(k, v) for k, v in dh if v[2] == unit]
        if sel:
            ax.errorbar(
                np.arange(len(sel)),
                [v[0] * scale for _, v in sel],
                yerr=[v[1] * scale for _, v in sel],
                fmt="o",
                capsize=3,
                label="estimate ± 1 std. error",
            )
            ax.set_xticks(np.arange(len(sel)), [k for k, _ in sel], rotation=60)
        ax.axhline(0.0, color="k", lw=0.8, label="nominal")
        ax.set_xlabel("parameter")
        ax.set_ylabel(label)
        ax.legend()
    fig.suptitle(f"estimated {parameter_kind(result.robot)} errors ({rep['choice']})")
    fig.tight_layout()
    return fig


def accuracy_figure(workspace, data, heldout, noise_mm: float):
    """The accuracy map: the calibrated model's predicted position standard deviation over the
    workspace (top and side views, base frame), beside the measured held-out errors at the data's
    poses (side view). ``workspace`` and ``data`` are ``(positions (K, 3) in the robot's base
    frame, predicted sigma (K,))`` of sampled reachable poses and of the data's poses;
    ``heldout (K,)`` the data poses' measured held-out errors (NaN: a pose left out, an outlier),
    ``noise_mm`` the fit's noise as an RMS distance, which a held-out error adds to the model's."""
    (pw, sw), (pd, sd) = workspace, data
    scored = np.isfinite(heldout)  # the measured and the predicted RMS over the same poses
    pd, sd, heldout = pd[scored], sd[scored], np.asarray(heldout)[scored]
    radius = lambda p: np.hypot(p[:, 0], p[:, 1])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), layout="constrained")
    views = ((lambda p: p[:, 0], 1, "x (mm)", "y (mm)"), (radius, 2, "distance from the base z axis (mm)", "z (mm)"))
    for ax, (hor, j, xl, yl) in zip(axes[:2], views):
        sc = ax.scatter(hor(pw), pw[:, j], c=sw, s=10, cmap="viridis", vmin=float(sw.min()), vmax=float(sw.max()))
        ax.scatter(hor(pd), pd[:, j], s=12, marker="x", color="r", lw=0.8, label="data poses")
        ax.set(xlabel=xl, ylabel=yl)
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="upper right")
    axes[0].set_title(f"predicted std. dev. of the model at {len(sw)} sampled poses (top view)", fontsize=10)
    axes[1].set_title("the same, side view", fontsize=10)
    fig.colorbar(sc, ax=axes[1], label="predicted std. dev. (mm)", shrink=0.9)
    rms = lambda v: float(np.sqrt(np.mean(np.square(v))))
    ax = axes[2]
    sc = ax.scatter(radius(pd), pd[:, 2], c=heldout, s=30, cmap="magma_r", vmin=0.0)
    ax.set(xlabel="distance from the base z axis (mm)", ylabel="z (mm)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(
        f"measured held-out error at the data poses: RMS {rms(heldout):.3g} mm\n"
        f"predicted RMS {rms(np.sqrt(sd**2 + noise_mm**2)):.3g} mm (model {rms(sd):.3g}, noise {noise_mm:.3g})",
        fontsize=10,
    )
    fig.colorbar(sc, ax=ax, label="measured held-out error (mm)", shrink=0.9)
    return fig


def calibration_figures(result, out_dir) -> list[Path]:
    """Write ``pose_errors.png`` (held-out position error per pose, frames only vs calibrated)
    and ``parameters.png`` (estimated DH or joint-frame errors with 1-sigma error bars) into ``out_dir``.
    **Returns** the paths written."""
    out = Path(out_dir)
    paths = []
    for name, make in (("pose_errors.png", pose_errors_figure), ("parameters.png", parameters_figure)):
        fig = make(result)
        paths.append(out / name)
        write_figure(fig, paths[-1], dpi=120)
        plt.close(fig)
    return paths
