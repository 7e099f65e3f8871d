"""Plots of a data calibration (matplotlib, Agg backend: files only, no display)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_plots(result, out_dir) -> list[Path]:
    """Write ``pose_errors.png`` (held-out position error per pose, frames only vs calibrated)
    and ``parameters.png`` (estimated DH errors with 1-sigma error bars) into ``out_dir``.
    **Returns** the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    pp, rep = result.per_pose, result.report
    paths = []

    fig, ax = plt.subplots(figsize=(10, 4))
    x = np.arange(len(pp["rows"]))
    ax.bar(x - 0.2, pp["frames_only_heldout"], width=0.4, color="tab:gray",
           label=f"frames only (RMS {rep['frames_only_heldout_rms_mm']:.2f} mm)")
    ax.bar(x + 0.2, pp["heldout"], width=0.4, color="tab:blue",
           label=f"calibrated, {rep['choice']} (RMS {rep['heldout_rms_mm']:.2f} mm)")
    ax.set_xlabel("pose (CSV data row - 1)")
    ax.set_ylabel("held-out position error (mm)")
    ax.set_title(f"{rep['folds']}-fold cross-validation: error on poses not used for fitting")
    ax.legend()
    fig.tight_layout()
    paths.append(out / "pose_errors.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    dh = [(k, v) for k, v in result.deltas.items() if not k.startswith(("base_", "tool_"))]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, unit, scale, label in ((axes[0], "mm", 1.0, "length error (mm)"),
                                   (axes[1], "rad", 1e3, "angle error (mrad)")):
        sel = [(k, v) for k, v in dh if v[2] == unit]
        if sel:
            ax.errorbar(np.arange(len(sel)), [v[0] * scale for _, v in sel], yerr=[v[1] * scale for _, v in sel],
                        fmt="o", capsize=3, label="estimate ± 1 std. error")
            ax.set_xticks(np.arange(len(sel)), [k for k, _ in sel], rotation=60)
        ax.axhline(0.0, color="k", lw=0.8, label="nominal")
        ax.set_xlabel("parameter")
        ax.set_ylabel(label)
        ax.legend()
    fig.suptitle(f"estimated DH errors ({rep['choice']})")
    fig.tight_layout()
    paths.append(out / "parameters.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)
    return paths
