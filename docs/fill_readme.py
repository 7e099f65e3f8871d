"""Fill README numbers from the result files written by docs/make_results.sh (so every number
in the README comes from a command in the repo). Usage: python docs/fill_readme.py TEMPLATE > README.md"""
import json
import sys
from pathlib import Path

import jax

D = Path(__file__).parent
nf = json.loads((D / "reproduce/noise-free/summary.json").read_text())
ny = json.loads((D / "reproduce/noisy/summary.json").read_text())
mc = json.loads((D / "montecarlo/gn_1000.json").read_text())
fr = json.loads((D / "franka/report.json").read_text())
fd = json.loads((D / "franka/report_depth_scale.json").read_text())
fl = json.loads((D / "franka/report_camera_linear.json").read_text())
fq = json.loads((D / "franka/report_camera_quadratic.json").read_text())
fa = json.loads((D / "franka/report_camera_auto.json").read_text())
fs = json.loads((D / "franka/fold_seeds.json").read_text())
g = lambda v: f"{v:.3g}"
key = {"linear": "linear", "gn": "gn", "elimination": "elimination", "literal": "elimination-literal"}
vals = {"n_poses": nf["n_calibration_poses"], "n_inspect": nf["n_inspection_poses"], "jax": jax.__version__,
        "nf_nominal": g(nf["inspection_rms_mm"]["nominal"]), "n_nominal": g(ny["inspection_rms_mm"]["nominal"])}
for k, m in key.items():
    vals[f"nf_{k}"] = g(nf["inspection_rms_mm"][m])
    vals[f"nfp_{k}"] = g(nf["max_param_error"][m])
    vals[f"n_{k}"] = g(ny["inspection_rms_mm"][m])
    vals[f"np_{k}"] = g(ny["max_param_error"][m])
    vals[f"t_{k}"] = f"{ny['time_s'][m] * 1e3:.2f}"
    vals[f"c_{k}"] = f"{ny['compile_s'][m]:.1f}"
vals.update(mc_rps=f"{mc['robots_per_second']:,.0f}", mc_compile=f"{mc['compile_seconds']:.1f}",
            mc_eff=f"{mc['crlb_efficiency_mean']:.3f}", mc_val=f"{mc['validation_pos_rms_mm']:.4f}")
vals.update(fr_f_train=f"{fr['frames_only_train_rms_mm']:.2f}", fr_f_ho=f"{fr['frames_only_heldout_rms_mm']:.2f}",
            fr_f_max=f"{fr['frames_only_heldout_max_mm']:.2f}", fr_f_rot=f"{fr['frames_only_heldout_rot_rms_deg']:.2f}",
            fr_c_train=f"{fr['train_rms_mm']:.2f}", fr_c_ho=f"{fr['heldout_rms_mm']:.2f}",
            fr_c_max=f"{fr['heldout_max_mm']:.2f}", fr_c_rot=f"{fr['heldout_rot_rms_deg']:.2f}",
            fr_choice=fr["choice"], fd_train=f"{fd['train_rms_mm']:.2f}", fd_ho=f"{fd['heldout_rms_mm']:.2f}",
            fd_max=f"{fd['heldout_max_mm']:.2f}", fd_rot=f"{fd['heldout_rot_rms_deg']:.2f}", fd_choice=fd["choice"],
            fd_s=f"{fd['camera_parameters']['camera_depth_scale']['value'] * 100:.2f}",
            fl_train=f"{fl['train_rms_mm']:.2f}", fl_ho=f"{fl['heldout_rms_mm']:.3f}",
            fl_max=f"{fl['heldout_max_mm']:.2f}", fl_rot=f"{fl['heldout_rot_rms_deg']:.2f}", fl_choice=fl["choice"])
for k, rep in (("fq", fq), ("fa", fa)):
    vals.update({f"{k}_train": f"{rep['train_rms_mm']:.2f}", f"{k}_ho": f"{rep['heldout_rms_mm']:.3f}",
                 f"{k}_max": f"{rep['heldout_max_mm']:.2f}", f"{k}_rot": f"{rep['heldout_rot_rms_deg']:.2f}",
                 f"{k}_choice": rep["choice"]})
vals["fa_nested"] = ", ".join(c.split("camera ")[-1] for c in fa["nested_choices"])
for k, cam in (("sn", "none"), ("sd", "depth"), ("sl", "linear"), ("sq", "quadratic"), ("sa", "auto")):
    vals.update({f"{k}_{s}": f"{fs[cam][s + '_mm']:.3f}" for s in ("median", "min", "max")})
    vals[f"{k}_med"] = vals.pop(f"{k}_median")
sys.stdout.write(Path(sys.argv[1]).read_text().format(**vals))
