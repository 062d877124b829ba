"""How far the rays' meeting point (C_e) lands from the truth in the estimate's frame, against
the arc of the circle its views come from: a Monte Carlo of the state estimator's model.

    python3 docs/campaigns/tools/ray_arc_sim.py [ARC_DEG ...]

The circle is the mission's fine-localization circle: 10 m over the target, camera pitched 55°
down, flown at the speed of a 720° sweep in 92 s (the default mission's 1099 fine-localization
frames at 4 Hz over 3 targets), a keyframe every 1.5 s. The estimate walks
as `[estimator] preset = "gps"` does (Gauss–Markov position, σ 0.5 m horizontal, τ 30 s; the
vertical at the 0.3 m the rangefinder leaves; attitude σ 0.5°/0.5°/2°, τ 10 s), and each box's
centre is off by σ 2 px at f 381 px. The truth is the centroid moved by the estimate's mean
error over the views, as `localization_error_estimate_frame_m` has it. Needs numpy.
"""
import sys

import numpy as np

PITCH_DEG, HEIGHT_M, KEYFRAME_S, SWEEP_720_S = 55.0, 10.0, 1.5, 92.0
SIGMA_WALK_M, TAU_WALK_S = np.array([0.5, 0.5, 0.3]), 30.0
SIGMA_ATTITUDE_RAD, TAU_ATTITUDE_S = np.radians([0.5, 0.5, 2.0]), 10.0
BOX_PX, FOCAL_PX = 2.0, 381.0
FLIGHTS = 2000


def gauss_markov(rng, n, dt, sigma, tau):
    phi = np.exp(-dt / tau)
    x = np.zeros(n)
    x[0] = rng.normal() * sigma
    for k in range(1, n):
        x[k] = phi * x[k - 1] + np.sqrt(1 - phi ** 2) * sigma * rng.normal()
    return x


def across(d):
    a = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def one_flight(rng, arc_deg):
    radius = HEIGHT_M / np.tan(np.radians(PITCH_DEG))
    t = np.arange(0.0, SWEEP_720_S * arc_deg / 720.0, KEYFRAME_S)
    n = len(t)
    walk = np.stack([gauss_markov(rng, n, KEYFRAME_S, s, TAU_WALK_S) for s in SIGMA_WALK_M], 1)
    attitude = np.stack([gauss_markov(rng, n, KEYFRAME_S, s, TAU_ATTITUDE_S)
                         for s in SIGMA_ATTITUDE_RAD], 1)
    start = rng.uniform(0, 2 * np.pi)
    normal, rhs = np.zeros((3, 3)), np.zeros(3)
    for k in range(n):
        a = start + np.radians(arc_deg) * t[k] / t[-1] if n > 1 else start
        origin = np.array([radius * np.cos(a), radius * np.sin(a), HEIGHT_M])
        d = -origin / np.linalg.norm(origin)
        u1, u2 = across(d)
        d = d + (u1 * rng.normal() + u2 * rng.normal()) * BOX_PX / FOCAL_PX
        d = d / np.linalg.norm(d)
        d = d + np.cross(attitude[k], d)
        d /= np.linalg.norm(d)
        projector = np.eye(3) - np.outer(d, d)
        normal += projector
        rhs += projector @ (origin + walk[k])
    return np.linalg.solve(normal, rhs) - walk.mean(0)


def main(arcs):
    print(f"arc   |z| median  |z| p90  3D p90  over 0.5 m  ({FLIGHTS} flights each)")
    for arc in arcs:
        # Each arc its own stream, so an arc's figures do not depend on which others run.
        rng = np.random.default_rng(int(arc * 10))
        errors = np.array([one_flight(rng, arc) for _ in range(FLIGHTS)])
        norms = np.linalg.norm(errors, axis=1)
        print(f"{arc:4.0f}°  {np.median(abs(errors[:, 2])):9.2f}  {np.quantile(abs(errors[:, 2]), 0.9):7.2f}"
              f"  {np.quantile(norms, 0.9):6.2f}  {100 * np.mean(norms > 0.5):8.1f}%")


if __name__ == "__main__":
    main([float(a) for a in sys.argv[1:]] or [180.0, 230.0, 270.0, 330.0, 360.0, 720.0])
