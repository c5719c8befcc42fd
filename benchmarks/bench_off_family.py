"""``abu measure`` on recordings outside the family the other benchmarks draw.

``bench_coverage.py`` renders ``twin.scenario.random_scenario(seed)``: 4500 frames/s, 3072
frames, 256 px, 8-bit, a camera at ~0.3 mm/px. Real cameras differ, and so will independent
checks. Each variant here renders the same scenarios with one thing changed (the frame rate,
the record's length, the frame size, the magnification, the sample format or tone curve,
stuck sensor pixels, the second highlight model; the view mirrored, upside down or turned a
quarter; an exposure of 0.95 of the frame interval; strong vignetting or a light falling off
across the frame; RGB colour frames; a 4 mm ball or a 9 mm path radius (given with --d, --l);
black markers on white paper (``--dark-markers``); a 320 x 256 sensor; a rolling shutter read
over a frame interval (``rolling_lt``: with ``--line-time`` stated); one frame dropped from the file) and runs ``abu measure`` with its default
options (``--ball-reflections 2`` where the ball shows two). Printed per variant: runs,
measured, measured with a null bound, intervals with both bounds holding the true mu (of
those with both), the median relative width, the onset brackets [t_slip_low, t_slip_high]
holding the simulated first slip, the
refusals (their first words), the median CPU time of ``abu measure`` (the process's, from
``wait4``; the machine may be shared) and the largest peak RSS of its runs [MB] (memory-mapped
frames included).

    nice python benchmarks/bench_off_family.py --first 20000 --seeds 4 --jobs 2
    nice python benchmarks/bench_off_family.py --variants fps1500,hotpix --seeds 8

Seeds from 20000 on were drawn for this benchmark; nothing was tuned on them.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from multiprocessing import Pool
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

#: The family's record length [s] (3072 frames at 4500 frames/s).
DUR_S = 3072 / 4500.0
#: variant -> (random_scenario options, magnification, post-processing of the frames); the
#: option ``lead_s`` holds the drive's starting speed that much longer (``twin.scenario.
#: with_lead``: a late slip in a long record; drives that start accelerating are "n/a")
VARIANTS = {
    "base": ({}, None, None),
    "fps1500": ({"fps": 1500.0, "n_frames": round(DUR_S * 1500)}, None, None),
    "fps2500": ({"fps": 2500.0, "n_frames": round(DUR_S * 2500)}, None, None),
    "fps8000": ({"fps": 8000.0, "n_frames": round(DUR_S * 8000)}, None, None),
    "fps12000": ({"fps": 12000.0, "n_frames": round(DUR_S * 12000)}, None, None),
    "long6000": ({"n_frames": 6000}, None, None),
    "long12000": ({"n_frames": 12000}, None, None),
    "long20000": ({"n_frames": 20000}, None, None),
    "lead1.5": ({"lead_s": 1.5}, None, None),
    "size200": ({"size": 200}, None, None),
    "size512": ({"size": 512}, None, None),
    "zoom1.5": ({"size": 384}, 1.5, None),
    "zoom2": ({"size": 512}, 2.0, None),
    "zoom0.7": ({}, 0.7, None),
    "zoom0.5": ({}, 0.5, None),
    "u16x256": ({}, None, "x256"),
    "gamma": ({}, None, "gamma"),
    "dim": ({}, None, "dim"),
    "noisy": ({}, None, "noisy"),
    "hotpix": ({}, None, "hotpix"),
    "deadpix": ({}, None, "deadpix"),
    "alt": ({"lighting": "two_spot_alt"}, None, None),
    "mirror": ({}, None, "mirror"),
    "flipud": ({}, None, "flipud"),
    "rot90": ({}, None, "rot90"),
    "longexp": ({}, None, None),
    "vignette": ({}, None, None),
    "gradient": ({}, None, "gradient"),
    "rgb": ({}, None, "rgb"),
    "ball4mm": ({}, None, None),
    "path9mm": ({}, None, None),
    "darkmark": ({}, None, None),
    "wide": ({"size": 320}, None, "crop256"),
    "rolling": ({}, None, None),
    "rolling_lt": ({}, None, None),
    "drop1": ({}, None, "drop1"),
}
#: variant -> the scenario changed after drawing, and the ``abu measure`` options it needs
#: (a user states the ball's size and path radius: --d, --l)
SCENARIO_CHANGES = {
    # an exposure of 0.95 of the frame interval (the family: 0.1-0.5), sampled finely enough
    "longexp": (lambda s: s.with_(optics=replace(s.optics, exposure_fraction=0.95),
                                  blur_samples=24), []),
    # a wide-angle lens stopped down: 1/(1+2 r^2)^2, 1/9 in the corners (the family: <= 0.5)
    "vignette": (lambda s: s.with_(optics=replace(s.optics, vignetting=2.0)), []),
    "ball4mm": (lambda s: s.with_(ball=replace(s.ball, d=4.0e-3)), ["--d", "0.004"]),
    "path9mm": (lambda s: s.with_(ball=replace(s.ball, l=9.0e-3)), ["--l", "0.009"]),
    # black markers on white paper, the paper exposed to 150 grey levels (the ball, lit as
    # before, is then darker than the paper around it but for its highlights)
    "darkmark": (lambda s: s.with_(albedo_bg=0.8, albedo_marker=0.08, exposure_scale=150.0),
                 ["--dark-markers"]),
}
#: Rolling shutter: rows read out one after another over this fraction of a frame interval
#: (a CMOS sensor at its full frame rate), top row first.
ROLLING_READOUT = 1.0


def postprocess(frames: np.ndarray, how: str) -> np.ndarray:
    """The frames as another camera or a defective sensor would give them."""
    rng = np.random.default_rng(7)
    h, w = frames.shape[1:]
    if how == "x256":      # 16-bit file, the 8 bits in the high byte
        return frames.astype(np.uint16) * 256
    if how == "gamma":     # a display tone curve
        return np.rint(255.0 * (frames / 255.0) ** (1 / 2.2)).astype(np.uint8)
    if how == "dim":       # 0.4 of the exposure
        return np.rint(frames * 0.4).astype(np.uint8)
    if how == "mirror":    # seen from below (or a drive turning the other way): left-right
        return np.ascontiguousarray(frames[:, :, ::-1])
    if how == "flipud":
        return np.ascontiguousarray(frames[:, ::-1])
    if how == "rot90":     # the camera turned a quarter
        return np.ascontiguousarray(np.rot90(frames, axes=(1, 2)))
    if how == "gradient":  # one side lamp: the light falls from 1 to 0.4 across the frame
        ramp = np.linspace(1.0, 0.4, w, dtype=np.float32)
        return np.rint(frames * ramp).astype(np.uint8)
    if how == "drop1":     # frame 1000 lost on the way, the time base still even
        return np.delete(frames, 1000, axis=0)
    if how == "crop256":   # a 320 x 256 sensor: the middle 256 rows
        return np.ascontiguousarray(frames[:, (h - 256) // 2:(h + 256) // 2])
    if how == "rgb":       # a colour camera under warm light: RGB samples, blue weak
        cast = np.array([1.0, 0.85, 0.6], dtype=np.float32)
        return np.clip(np.rint(frames[..., None] * cast), 0, 255).astype(np.uint8)
    if how == "noisy":     # +5 grey levels of white noise
        return np.clip(np.rint(frames + rng.normal(0, 5.0, frames.shape)), 0, 255).astype(
            np.uint8)
    out = frames.copy()    # 30 pixels stuck at 255 (hot) or 0 (dead)
    out[:, rng.integers(0, h, 30), rng.integers(0, w, 30)] = 255 if how == "hotpix" else 0
    return out


def run(job: tuple[str, int, str]) -> dict:
    """Render one variant of one seed and measure it; the result row."""
    import tifffile

    from abu_model.errors import ParameterError
    from measurement.imaging.frame_rate import tiff_metadata
    from twin.scenario import magnified, random_scenario, render_scenario_frames, \
        rolling_shutter_positions, scenario_meta, simulate_scenario, with_lead

    variant, seed, work = job
    options, zoom, post = VARIANTS[variant]
    change, extra = SCENARIO_CHANGES.get(variant, (None, []))
    row: dict = {"variant": variant, "seed": seed}
    lead_s = options.get("lead_s", 0.0)
    scn = random_scenario(seed, **{k: v for k, v in options.items() if k != "lead_s"})
    if zoom:
        scn = magnified(scn, zoom)
    if change:
        scn = change(scn)
    state, pos = simulate_scenario(scn)
    if lead_s:
        try:
            scn, state, pos = with_lead(scn, state, lead_s)
        except ParameterError:
            return {**row, "na": True}
    rolling = variant in ("rolling", "rolling_lt")
    frames = render_scenario_frames(scn, state, rolling_shutter_positions(
        scn, state, pos, ROLLING_READOUT) if rolling else pos)
    if variant == "rolling_lt":   # the camera's line time stated: abu measure --line-time
        extra = extra + ["--line-time", repr(ROLLING_READOUT / scn.fps / scn.height)]
    if post:
        frames = postprocess(frames, post)
    meta = scenario_meta(scn, state, pos)
    d = Path(work) / f"{variant}_{seed}"
    d.mkdir(parents=True)
    tifffile.imwrite(d / "frames.tif", frames, contiguous=True,
                     photometric="rgb" if frames.ndim == 4 else "minisblack",
                     metadata=tiff_metadata(scn.fps, 0.0))
    cmd = [sys.executable, "-m", "abu.cli.main", "measure", str(d / "frames.tif"), "--out",
           str(d / "m"), "--no-plots", "--quiet"] + extra
    if int(meta["ball_reflections"]) == 2:
        cmd += ["--ball-reflections", "2"]
    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1")
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    err = p.stderr.read().decode(errors="replace")
    _, status, usage = os.wait4(p.pid, 0)
    row.update(mu=meta["mu"], exit=os.waitstatus_to_exitcode(status),
               cpu_s=usage.ru_utime + usage.ru_stime,
               peak_mb=usage.ru_maxrss / 1024.0)   # peak RSS of abu measure [MB] (Linux: kB)
    summary = d / "m" / "summary.json"
    s = json.loads(summary.read_text()) if row["exit"] == 0 else None
    shutil.rmtree(d)   # a 512 px or 16-bit recording is 0.4-0.8 GB: one at a time on disk
    if s is None:
        row["error"] = (err.strip().splitlines() or ["?"])[-1]
        return row
    lo, hi = s.get("mu_low"), s.get("mu_high")
    row.update(status=s.get("status"), mu_low=lo, mu_high=hi, t_slip_low=s.get("t_slip_low"),
               t_slip_high=s.get("t_slip_high"), t_slip_true=meta["simulation"]["t_slip_s"])
    if lo is not None and hi is not None:   # a null bound is counted apart, never as a hit
        row.update(covered=lo <= meta["mu"] <= hi, width=(hi - lo) / (0.5 * (hi + lo)))
    return row


def _bracketed(r: dict) -> bool | None:
    """Whether [t_slip_low, t_slip_high] holds the true onset (None: a bound or it missing)."""
    lo, hi, t = r.get("t_slip_low"), r.get("t_slip_high"), r.get("t_slip_true")
    return None if None in (lo, hi, t) else lo <= t <= hi


def _refusal(error: str) -> str:
    """A refusal's words, without the command's prefix and the temporary file's path."""
    return error.split("error: ", 1)[-1].split("frames.tif", 1)[-1].lstrip(",: ")[:70]


def report(rows: list[dict]) -> None:
    print(f"{'variant':10s} {'runs':>4s} {'measured':>8s} {'null bound':>10s} {'covered':>8s} "
          f"{'median width':>12s} {'onset in':>8s} {'CPU s':>6s} {'peak MB':>7s}  refusals")
    for v in VARIANTS:
        rs = [r for r in rows if r["variant"] == v and not r.get("na")]
        na = sum(1 for r in rows if r["variant"] == v and r.get("na"))
        if na:
            print(f"{v:10s} {na} seed(s) n/a (the drive starts accelerating: no lead)")
        if not rs:
            continue
        ok = [r for r in rs if r["exit"] == 0]
        both = [r for r in ok if "width" in r]     # both bounds finite
        widths = [r["width"] for r in both]
        onsets = [b for b in map(_bracketed, ok) if b is not None]
        refused = sorted({_refusal(r["error"]) for r in rs if r["exit"]})
        print(f"{v:10s} {len(rs):4d} {len(ok):8d} {len(ok) - len(both):10d} "
              f"{sum(r['covered'] for r in both):5d}/{len(both):<2d} "
              f"{100 * np.median(widths) if widths else float('nan'):11.1f}% "
              f"{sum(onsets):5d}/{len(onsets):<2d} "
              f"{np.median([r['cpu_s'] for r in rs]):6.2f} "
              f"{max(r['peak_mb'] for r in rs):7.0f}  {'; '.join(refused)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--first", type=int, default=20000, help="first seed")
    ap.add_argument("--seeds", type=int, default=4, help="seeds per variant")
    ap.add_argument("--variants", default=",".join(VARIANTS),
                    help=f"comma-separated, of: {', '.join(VARIANTS)}")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", default=None, help="write the rows as JSON lines here")
    args = ap.parse_args()
    if args.seeds < 1 or args.jobs < 1:
        ap.error(f"--seeds {args.seeds}, --jobs {args.jobs}: expected at least 1 each")
    variants = args.variants.split(",")
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        ap.error(f"--variants: unknown {', '.join(bad)}; expected some of {', '.join(VARIANTS)}")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_off_family_") as work:
        jobs = [(v, s, work) for v in variants for s in range(args.first, args.first + args.seeds)]
        with Pool(args.jobs, maxtasksperchild=1) as pool:
            rows = pool.map(run, jobs, chunksize=1)
    if args.out:
        Path(args.out).write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(f"seeds {args.first}-{args.first + args.seeds - 1} per variant; abu measure with its "
          f"defaults; {time.perf_counter() - t0:.0f} s wall")
    report(rows)


if __name__ == "__main__":
    main()
