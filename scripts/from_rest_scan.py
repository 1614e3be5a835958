#!/usr/bin/env python3
"""The from-rest scan: the roll-up from rest (examples/scenes/rollup_from_rest.toml) with each
dissipation parameter alone at 0.5 (EDMC-1: chi_gamma, chi_omega, chi_v, chi_nu; EDMC-2:
alpha_gv, alpha_gn, alpha_ov, alpha_on) and EM, at 40 log-spaced time steps in [0.02, 0.3],
to t = 2, the fixed-step scheme (--cutback 0). Prints every failed cell with its reason and
the counts: completed, failed with a scheme reason (an element turned past its limit, the
energy or identity check), failed as a solver stall (Newton did not converge).

    scripts/from_rest_scan.py [BINARY]      # default target/release/cosserat
"""
import json
import math
import re
import subprocess
import sys
import tempfile
from pathlib import Path

root = Path(__file__).resolve().parent.parent
binary = sys.argv[1] if len(sys.argv) > 1 else str(root / "target/release/cosserat")
base = (root / "examples/scenes/rollup_from_rest.toml").read_text()
params = [("em", None)] + [("edmc1", p) for p in ("chi_gamma", "chi_omega", "chi_v", "chi_nu")] + [
    ("edmc2", p) for p in ("alpha_gv", "alpha_gn", "alpha_ov", "alpha_on")
]
dts = [0.02 * (0.3 / 0.02) ** (k / 39) for k in range(40)]
counts = {"completed": 0, "scheme": 0, "stall": 0}
with tempfile.TemporaryDirectory() as tmp:
    for scheme, p in params:
        block = f'scheme = "{scheme}"\n' + (f"{p} = 0.5\n" if p else "")
        text = re.sub(r'scheme = "edmc2"\nalpha_ov = 0.5\n', block, base)
        scene = Path(tmp) / f"{scheme}_{p}.toml"
        scene.write_text(text)
        for dt in dts:
            out = Path(tmp) / "out"
            subprocess.run(
                [binary, "run", str(scene), "--set", f"integrator.dt={dt!r}", "--cutback", "0",
                 "--out", str(out)],
                check=True, capture_output=True,
            )
            s = json.loads((out / "summary.json").read_text())
            if s["status"] == "completed":
                counts["completed"] += 1
                continue
            reason = s.get("reason") or ""
            kind = "stall" if "Newton did not converge" in reason and "turned" not in reason else "scheme"
            counts[kind] += 1
            print(f"{scheme} {p or '-'} dt={dt:.4g}: t={s.get('t_reached')}: {reason[:160]}")
total = sum(counts.values())
print(f"{total} cells: {counts['completed']} completed, {counts['scheme']} failed with a scheme "
      f"reason, {counts['stall']} solver stalls")
