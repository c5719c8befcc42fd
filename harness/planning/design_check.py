"""The co-simulation check of a staircase design (``abu design`` without ``--no-check``)."""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from harness.planning.design import CHECK_COMM_STEP, Design, predict

def check_design(design: Design, mus: np.ndarray | None = None, fmu_dir: Any = None
                 ) -> list[dict[str, Any]]:
    """Co-simulate the design on the FMUs at ``mus`` (default: the range's ends).

    Each row: mu, t_slip_s, mu_low, mu_high (the co-simulation's bounds), first_step_stuck,
    slip_inside (edge included), brackets.
    """
    from abu_model.params import PlantParams

    from harness.experiments.staircase import StaircaseExperiment, run_staircase

    spec = design.spec
    mus = np.array([spec.mu_lo, spec.mu_hi]) if mus is None else np.asarray(mus, float)
    stair = design.staircase
    second = stair.step_times[1]
    t_pred = predict(spec, stair, mus)["t_slip_s"]
    rows = []
    for mu, tp in zip(mus, t_pred):
        plant = PlantParams(ball=replace(spec.ball, mu=float(mu), mu_d=None),
                            tau_motor=spec.drive.tau_motor)
        # Stop 30 ms after the predicted slip (the slipping ball is the costly part): a slip
        # later than that, but inside the record, would fail the check, never pass it.
        t_end = spec.record_s if not np.isfinite(tp) else min(spec.record_s, float(tp) + 0.03)
        # CHECK_COMM_STEP: the stepping mode the design is validated in
        exp = StaircaseExperiment(plant, stair.omega0, stair.omega_end, stair.t0, stair.te,
                                  t_end=t_end, step=stair.step, rounding=stair.rounding,
                                  zeta=spec.drive.zeta, omega_n=spec.drive.omega_n,
                                  comm_step=CHECK_COMM_STEP)
        s = run_staircase(exp, fmu_dir).summary
        ts = s["t_slip"]
        rows.append({"mu": float(mu), "t_slip_s": ts, "mu_low": s["mu_low"],
                     "mu_high": s["mu_high"],
                     "first_step_stuck": ts is None or ts > second,
                     "slip_inside": ts is not None
                     and spec.edge_s - 1e-3 <= ts <= spec.record_s - spec.edge_s + 1e-3,
                     "brackets": bool(s.get("brackets_mu"))})
    return rows
