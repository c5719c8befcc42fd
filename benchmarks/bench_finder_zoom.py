"""Does the marker finder read first frames of cameras closer or farther than the family's?

For each seed of the harsh family, ``twin.scenario.random_scenario(seed)`` is filmed ``--zoom``
times closer (``twin.scenario.magnified``; frames ``max(256, 256 x zoom)`` px wide), its first
frame rendered, and ``measurement.imaging.markers.find_markers`` run on it. Printed: how many
frames it read right (every marker within 3 x zoom px of its true centre), refused
(``MarkerError``, naming the candidates) and read wrong (the target: none). ::

    python benchmarks/bench_finder_zoom.py --zoom 2 --first 5000 --n 150
    python benchmarks/bench_finder_zoom.py --zoom 0.7 --first 6000 --n 100

Measured (twelfth session): 2x, seeds 5000-5149 and 6000-6149, 300 of 300 right (the finder
before its second looks: 297, 3 refused); 1x seeds 6000-6149 150 of 150, 0.7x seeds 6000-6099
100 of 100 (as before).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from measurement.imaging.markers import MarkerError, find_markers  # noqa: E402
from twin.scenario import (magnified, random_scenario, render_scenario_frames,  # noqa: E402
                          simulate_scenario)


def first_frame(seed: int, zoom: float):
    """(first frame, true centres (3, 2) [px], the ball's reflections) of the seed at zoom."""
    scn = random_scenario(seed, n_frames=1000, size=max(256, int(round(256 * zoom))))
    scn = (magnified(scn, zoom) if zoom != 1 else scn).with_(n_frames=2)
    state, pos = simulate_scenario(scn)
    frame = render_scenario_frames(scn, state, pos)[0]
    return frame, np.array([pos["centre"][0], pos["cd"][0], pos["ball"][0]]), \
        int(scn.lighting.reflections)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zoom", type=float, default=2.0, help="magnification over the family's")
    ap.add_argument("--first", type=int, default=5000, help="first seed")
    ap.add_argument("--n", type=int, default=150, help="seeds")
    a = ap.parse_args()
    right, refused, wrong = [], [], []
    for seed in range(a.first, a.first + a.n):
        frame, truth, reflections = first_frame(seed, a.zoom)
        try:
            seeds, _ = find_markers(frame, ball_reflections=reflections)
        except MarkerError as exc:
            refused.append(seed)
            print(f"  seed {seed} refused: {str(exc)[:140]}")
            continue
        ok = np.hypot(*(seeds - truth).T).max() < 3.0 * a.zoom
        (right if ok else wrong).append(seed)
    print(f"zoom {a.zoom:g}, seeds {a.first}-{a.first + a.n - 1}: right {len(right)}, refused "
          f"{len(refused)} {refused}, wrong {len(wrong)} {wrong} (target: none wrong)")


if __name__ == "__main__":
    main()
