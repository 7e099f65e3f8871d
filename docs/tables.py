"""Print the tables of the docs from the result files that ``docs/make_results.sh`` writes, and
with ``--write`` put them into the docs pages between ``<!-- table:NAME -->`` and
``<!-- /table -->``, so every number in the docs comes from a command in the repository.

Usage (repository root, venv active): python docs/tables.py [--write]
"""

import json
import re
import sys
from pathlib import Path

D = Path(__file__).resolve().parent


def load(rel):
    return json.loads((D / rel).read_text())


def machine(m: dict) -> str:
    return f"{m['cores']} cores {m['cpu']} ({m['device']}), jax {m['jax']}"


def g(v):
    return f"{v:.3g}"


def chosen(r: dict) -> str:
    """The chosen candidate, saying so when it came with compliances and pruned every one."""
    pruned = "+ compliance" in r["choice"] and not r["compliance"]
    return r["choice"] + (" (every compliance pruned)" if pruned else "")


def reproduction() -> str:
    nf, ny = load("reproduce/noise-free/summary.json"), load("reproduce/noisy/summary.json")
    methods = [
        ("linear", "one-shot LS"),
        ("gn", "Gauss–Newton"),
        ("elimination", "elimination (robust)"),
        ("elimination-literal", "elimination (literal)"),
    ]
    rows = ["| | nominal | " + " | ".join(t for _, t in methods) + " |", "|---" * (len(methods) + 2) + "|"]
    for lab, s in (("noise-free", nf), (f"{ny['noise']['sigma_pos_mm']} mm / {ny['noise']['sigma_rot_rad']} rad", ny)):
        rows.append(
            f"| {lab}: inspection RMS (mm) | {g(s['inspection_rms_mm']['nominal'])} | "
            + " | ".join(g(s["inspection_rms_mm"][m]) + ("" if s["converged"][m] else " (failed)") for m, _ in methods)
            + " |"
        )
        rows.append(
            f"| {lab}: max parameter error | | " + " | ".join(g(s["max_param_error"][m]) for m, _ in methods) + " |"
        )
    rows.append(
        "| time per calibration, median (ms) | | "
        + " | ".join(f"{ny['time_s'][m] * 1e3:.2f}" for m, _ in methods)
        + " |"
    )
    rows.append("| compile time (s) | | " + " | ".join(f"{ny['compile_s'][m]:.1f}" for m, _ in methods) + " |")
    rows.append("")
    rows.append(
        f"{nf['n_calibration_poses']} calibration poses, {nf['n_inspection_poses']} inspection poses; "
        f"machine: {machine(ny['machine'])}."
    )
    return "\n".join(rows)


def montecarlo() -> str:
    mc = load("montecarlo/gn_1000.json")
    return "\n".join(
        [
            "| robots | poses | robots/s | compile (s) | converged | CRLB efficiency (mean) | validation RMS (mm) |",
            "|---|---|---|---|---|---|---|",
            f"| {mc['n_robots']} | {mc['n_poses']} | {mc['robots_per_second']:,.0f} | {mc['compile_seconds']:.1f} | "
            f"{mc['converged_fraction']:.3f} | {mc['crlb_efficiency_mean']:.3f} | {mc['validation_pos_rms_mm']:.4f} |",
            "",
            f"machine: {machine(mc['machine'])}.",
        ]
    )


FRANKA = [
    ("report.json", "calibrated, no camera model"),
    ("report_depth_scale.json", "`--camera-model depth`"),
    ("report_camera_linear.json", "`--camera-model linear`"),
    ("report_camera_quadratic.json", "`--camera-model quadratic`"),
    ("report_camera_auto.json", "`--camera-model auto` (camera model chosen by cross-validation too)"),
]


def franka() -> str:
    reps = [(load(f"franka/{f}"), lab) for f, lab in FRANKA]
    r0 = reps[0][0]
    rows = [
        "| model | chosen set | train RMS (mm) | held-out: new postures (mm) | beyond the ranges (mm) "
        "| held-out max (mm) | held-out rotation RMS (deg) |",
        "|---|---|---|---|---|---|---|",
        f"| frames only (nominal DH) | | {r0['frames_only_train_rms_mm']:.2f} | "
        f"{r0['frames_only_heldout_rms_mm']:.3f} | {r0['frames_only_extrapolation_rms_mm']:.3f} | "
        f"{r0['frames_only_heldout_max_mm']:.2f} | {r0['frames_only_heldout_rot_rms_deg']:.2f} |",
    ]
    for r, lab in reps:
        rows.append(
            f"| {lab} | {chosen(r)} | {r['train_rms_mm']:.2f} | {r['heldout_rms_mm']:.3f} | "
            f"{r['extrapolation_rms_mm']:.3f} | {r['heldout_max_mm']:.2f} | {r['heldout_rot_rms_deg']:.2f} |"
        )
    rows.append("")
    rows.append(
        f"{r0['poses']} poses ({len(r0['outliers'])} found outliers left out), nested cross-validation: "
        f"{r0['folds']}-fold and {r0['range_end_folds']} range-end folds."
    )
    return "\n".join(rows)


def fold_seeds() -> str:
    fs = load("franka/fold_seeds.json")
    rows = ["| camera model | held-out RMS median (mm) | min | max |", "|---|---|---|---|"]
    for cam, r in fs.items():
        rows.append(f"| {cam} | {r['median_mm']:.3f} | {r['min_mm']:.3f} | {r['max_mm']:.3f} |")
    return "\n".join(rows)


def tiago() -> str:
    rows = [
        "| model | point 1 alone: train | new postures | beyond the ranges | all four points: train | new postures "
        "| beyond the ranges | point 1 of four: new postures | outliers left out (one point; four) | chosen (auto) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for params, label in (
        ("frames", "registration only (base + points)"),
        ("offsets", "+ joint offsets"),
        ("all", "full joint-frame model, no prior"),
        ("auto", "auto (the default)"),
    ):
        one, four = load(f"tiago/{params}_1pt.json"), load(f"tiago/{params}_4pt.json")
        choice = f"{chosen(one)}; {chosen(four)}" if params == "auto" else ""
        rows.append(
            f"| {label} | {one['train_rms_mm']:.2f} | {one['heldout_rms_mm']:.2f} | {one['extrapolation_rms_mm']:.2f} "
            f"| {four['train_rms_mm']:.2f} | {four['heldout_rms_mm']:.2f} | {four['extrapolation_rms_mm']:.2f} "
            f"| {four['heldout_points_rms_mm'][0]:.2f} | {len(one['outliers'])}; {len(four['outliers'])} | {choice} |"
        )
    rows.append("")
    rows.append(
        f"RMS of point error norms, mm; {one['poses']} postures, less the outliers each run's detection found "
        f"and left out; nested cross-validation: {one['folds']}-fold (new postures) and "
        f"{four['range_end_folds']} range-end folds (beyond the ranges)."
    )
    return "\n".join(rows)


def _study_rows(rel: str, label: str) -> list[tuple[str, str, list[str]]]:
    """The rows of a study's text tables (``docs/studies/*.txt``: a heading line per data set,
    right-aligned columns) whose label starts with ``label``: ``(heading, label, figures)``."""
    out, heading = [], ""
    for line in (D / rel).read_text().splitlines():
        if line and not line[0].isspace():
            heading = line
        m = re.match(r"^\s*(\S.*?)\s{2,}([-\d.]+(?:\s+[-\d.]+)*)\s*$", line)
        if m and m.group(1).startswith(label):
            out.append((heading, m.group(1), m.group(2).split()))
    return out


SCORING_DATA = {"TIAGo": "TIAGo, 4 points", "Franka": "Franka, poses"}


def scoring_rule() -> str:
    rows = ["| data | rule | tomorrow RMS of the choice (mm) | regret (mm) | rank correlation |", "|---" * 5 + "|"]
    last = None
    for heading, rule, (rms, regret, rank) in _study_rows("studies/scoring_rule.txt", "K-fold"):
        data = next(v for k, v in SCORING_DATA.items() if heading.startswith(k))
        cell = f" {data} " if data != last else " "
        rows.append(f"|{cell}| {rule} | {rms} | {regret} | {rank} |")
        last = data
    return "\n".join(rows)


CAMERA_WAYS = {
    "jaxcal": "jaxcal (camera unknowns free, not pruned)",
    "camera under the prior": "camera unknowns under the candidate's scaled prior",
    "camera pruned": "camera unknowns pruned like the others",
    "prune every candidate": "every candidate pruned, the lowest pruned score chosen",
    "prune by score": "pruning by score (backward stepwise) instead of by `t`",
    "+ joint harmonics": "with a once-per-turn joint angle error (`sin q`, `cos q`) as candidates",
}


def camera_selection() -> str:
    rows = ["| way of choosing | tomorrow RMS (mm) | regret (mm) |", "|---|---|---|"]
    found = {way: figs for _, way, figs in _study_rows("studies/camera_selection.txt", "")}
    for way, label in CAMERA_WAYS.items():
        rms, regret = found[way]
        rows.append(f"| {label} | {rms} | {regret} |")
    return "\n".join(rows)


TABLES = {
    "reproduction": reproduction,
    "montecarlo": montecarlo,
    "franka": franka,
    "fold_seeds": fold_seeds,
    "tiago": tiago,
    "scoring_rule": scoring_rule,
    "camera_selection": camera_selection,
}
PAGES = ("reproduction.md", "franka.md", "tiago.md", "selection.md")


def main() -> None:
    made = {name: f() for name, f in TABLES.items()}
    if "--write" not in sys.argv[1:]:
        for name, text in made.items():
            print(f"## {name}\n\n{text}\n")
        return
    for page in PAGES:
        path = D / page
        text = path.read_text()
        for name, table in made.items():
            text = re.sub(
                rf"(<!-- table:{name} -->\n).*?(<!-- /table -->)",
                lambda m, t=table: m.group(1) + t + "\n" + m.group(2),
                text,
                flags=re.S,
            )
        path.write_text(text)


if __name__ == "__main__":
    main()
