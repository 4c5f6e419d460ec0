"""Chapter 5, section 2 (BAL I/O and the camera): 5.5 `read_bal`, 5.6 `bal_project`, the real BAL problem."""
from __future__ import annotations

import io
from functools import lru_cache

import numpy as np

from graders.kit import datasets
from graders.core.engine import Case, Exercise, Hint, OutputError, as_array, like, register, with_file
from graders.oracles.bundle_adjust import bal_project as gt_project

from graders.core.memo import cached, val
from .common import max_dist, rel_max, tuple_of_arrays
from .problems import distorted_args, make_problem


def gt_read_bal(path) -> tuple[np.ndarray, ...]:
    """Parse a BAL file (a path, or an open text stream) with numpy's reader: (cameras, points,
    cam_idx, pt_idx, obs)."""
    if hasattr(path, "read"):
        return _parse_bal(path)
    with open(path) as f:
        return _parse_bal(f)


def _parse_bal(f) -> tuple[np.ndarray, ...]:
    nc, n_pts, m = (int(v) for v in f.readline().split())
    table = np.loadtxt(f, max_rows=m, ndmin=2)
    rest = np.array(f.read().split(), dtype=float)  # any layout: BAL writes one number per line
    return (rest[:9 * nc].reshape(nc, 9), rest[9 * nc:9 * nc + 3 * n_pts].reshape(n_pts, 3),
            table[:, 0].astype(np.int64), table[:, 1].astype(np.int64), table[:, 2:4])


def bal_text(cameras, points, cam_idx, pt_idx, obs, per_line: int = 1) -> str:
    """A BAL file's text (numbers after the observations `per_line` to a line; BAL uses 1)."""
    lines = [f"{len(cameras)} {len(points)} {len(obs)}"]
    lines += [f"{c} {p}     {u:.15e} {v:.15e}" for c, p, (u, v) in zip(cam_idx, pt_idx, obs)]
    values = np.r_[np.ravel(cameras), np.ravel(points)]
    lines += [" ".join(f"{v:.17e}" for v in values[i:i + per_line]) for i in range(0, len(values), per_line)]
    return "\n".join(lines) + "\n"


def write_bal(path, cameras, points, cam_idx, pt_idx, obs, per_line: int = 1) -> None:
    """Write a BAL file (numbers after the observations `per_line` to a line; BAL uses 1)."""
    with open(path, "w") as f:
        f.write(bal_text(cameras, points, cam_idx, pt_idx, obs, per_line))


def cases_read_bal(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, per_line, kw in [("BAL layout, one number per line", 1, dict(n_cams=4, n_points=30)),
                               ("camera numbers 9 to a line", 9, dict(n_cams=6, n_points=50))]:
        prob = make_problem(rng, **kw)
        text = bal_text(prob["cameras"], prob["points"], prob["cam_idx"], prob["pt_idx"], prob["obs"], per_line)
        expected = gt_read_bal(io.StringIO(text))
        # 1e-9: the file holds 15-17 significant digits; parsing them is exact to ~1e-16 relative.
        out.append(Case(name, ("problem.txt",), expected, _metric_read, 1e-9, "rel.", convert=_convert_read,
                        call=with_file("problem.txt", text), key=f"synthetic-{per_line}-per-line"))
    if datasets.available("bal"):
        path = datasets.path("bal", "problem-49-7776-pre.txt")
        out.append(Case("real: BAL problem-49-7776-pre (49 cameras, 7,776 points, 31,843 observations)",
                        ("problem.txt",), _real_bal(), _metric_read, 1e-9, "rel.", convert=_convert_read,
                        call=with_file("problem.txt", path), key="real-bal-49", tags=("real",)))
    return out


@lru_cache(maxsize=1)
def _real_bal():
    return gt_read_bal(datasets.path("bal", "problem-49-7776-pre.txt"))


def load_bal_problem(n_cams: int | None = None) -> dict:
    """The real BAL problem-49-7776-pre as a problem dict (copies). n_cams: keep only the first
    n_cams cameras and the points they see at least twice (a subset that runs in a notebook)."""
    cams, pts, ci, pi, obs = (np.array(a) for a in _real_bal())
    if n_cams is not None and n_cams < len(cams):
        keep_obs = ci < n_cams
        counts = np.bincount(pi[keep_obs], minlength=len(pts))
        keep_obs &= counts[pi] >= 2
        used = np.flatnonzero(np.bincount(pi[keep_obs], minlength=len(pts)))
        remap = np.full(len(pts), -1)
        remap[used] = np.arange(len(used))
        cams, pts, ci, pi, obs = cams[:n_cams], pts[used], ci[keep_obs], remap[pi[keep_obs]], obs[keep_obs]
    return {"cameras": cams, "points": pts, "cam_idx": ci, "pt_idx": pi, "obs": obs}


def _convert_read(out, case):
    nc, n_pts, m = len(case.expected[0]), len(case.expected[1]), len(case.expected[2])
    return tuple_of_arrays(out, [(nc, 9), (n_pts, 3), (m,), (m,), (m, 2)],
                            ["cameras", "points", "cam_idx", "pt_idx", "obs"])


def _metric_read(out, expected):
    return max(rel_max(a, b) for a, b in zip(out, expected))


def _bug_read_cameras_transposed(case):
    cams, pts, ci, pi, obs = val(case.expected)
    return (cams.ravel().reshape(9, -1).T, pts, ci, pi, obs)


def _bug_read_uv_swapped(case):
    cams, pts, ci, pi, obs = val(case.expected)
    return (cams, pts, ci, pi, obs[:, ::-1])


def _bug_read_points_first(case):
    cams, pts, ci, pi, obs = val(case.expected)
    rest = np.r_[cams.ravel(), pts.ravel()]
    return (rest[3 * len(pts):].reshape(len(cams), 9), rest[:3 * len(pts)].reshape(len(pts), 3), ci, pi, obs)


def _metric_read_safe(case, out, wrong):
    try:
        return _metric_read(out, wrong) <= case.tol
    except Exception:
        return False


READ_HINTS = [
    Hint("the camera block looks read column by column: each camera's 9 numbers are consecutive "
         "(reshape(nc, 9), not reshape(9, nc).T).",
         lambda c, out: _metric_read_safe(c, out, _bug_read_cameras_transposed(c))),
    Hint("u and v are swapped: each observation line is `camera point u v`.",
         lambda c, out: _metric_read_safe(c, out, _bug_read_uv_swapped(c))),
    Hint("the camera block comes first after the observations (9 nc numbers), then the points (3 np): you read "
         "the points first.", lambda c, out: _metric_read_safe(c, out, _bug_read_points_first(c))),
]


def cases_bal_project(rng: np.random.Generator) -> list[Case]:
    from scipy.spatial.transform import Rotation
    out = []
    for name, kw in [("8 cameras, 150 points", dict(n_cams=8, n_points=150)),
                     ("30 cameras, 3,000 points (vectorise!)", dict(n_cams=30, n_points=3000, visibility=0.5))]:
        args = distorted_args(rng, make_problem(rng, **kw))
        # 1e-6 px: the same closed form in float64 on both sides (~1e-10 px apart).
        out.append(Case(name, args, gt_project(*args), max_dist, 1e-6, "px", shape=(len(args[2]), 2)))
    cams, pts, ci, pi = distorted_args(rng, make_problem(rng, n_cams=5, n_points=60))
    # Cameras 0 and 1 with the identity rotation (theta = 0 exactly) and a nearly-identity one
    # (1e-9 rad), moved so that they still look at the points (BAL cameras look down -Z).
    target = pts.mean(axis=0)
    for i, w in enumerate([np.zeros(3), 1e-9 * rng.normal(size=3) / np.sqrt(3)]):
        C = target + [0.0, 0.0, 3.0 * np.ptp(pts, axis=0).max()]
        cams[i, :3] = w
        cams[i, 3:6] = -Rotation.from_rotvec(w).apply(C)
    out.append(Case("rotation vectors of length 0 and 1e-9", (cams, pts, ci, pi), gt_project(cams, pts, ci, pi),
                    max_dist, 1e-6, "px", shape=(len(ci), 2), convert=_convert_small_rotations))
    return out


def _convert_small_rotations(out, case):
    """as_array, with a diagnosis when the non-finite pixels are those of the cameras with |w| ~ 0."""
    try:
        raw = np.asarray(out, dtype=float)
    except Exception:
        raw = None
    if raw is not None and raw.shape == case.shape and not np.isfinite(raw).all():
        cams, ci = case.args[0], case.args[2]
        bad_cams = np.unique(ci[~np.isfinite(raw).all(axis=1)])
        if np.all(np.linalg.norm(cams[bad_cams, :3], axis=1) < 1e-6):
            raise OutputError(f"non-finite pixels for the cameras with rotation vectors of length 0 and 1e-9 "
                              f"(cameras {bad_cams.tolist()}): k = w / |w| is 0/0 there. Use the Taylor series of "
                              f"sin(θ)/θ and (1 - cos θ)/θ² for small θ (or scipy's Rotation), never divide by θ.")
    return as_array(out, case)


def _project_variant(case, sign=-1.0, r_power=2, transpose=False, k2_power=4):
    """A slip's projection: p = sign P[:2] / P[2] from the course's own projection with f = 1 and no distortion
    (R^T: the rotation vector negated), then the slip's radial factor."""
    cams, pts, ci, pi = case.args
    plain = np.array(cams, float)
    plain[:, :3] *= -1.0 if transpose else 1.0
    plain[:, 6:9] = (1.0, 0.0, 0.0)
    p = -sign * gt_project(plain, pts, ci, pi)
    r = np.linalg.norm(p, axis=1)
    c = cams[ci]
    return (c[:, 6] * (1 + c[:, 7] * r**r_power + c[:, 8] * r**k2_power))[:, None] * p


PROJECT_HINTS = [
    like(lambda c: _project_variant(c, sign=1.0), "the sign of p: BAL cameras look down -Z, so p = -P[:2] / P[2]."),
    like(lambda c: _project_variant(c, transpose=True), "the rotation is inverted (R^T): BAL's P = R(w) X + t."),
    like(lambda c: _project_variant(c, r_power=1, k2_power=2),
         "the radial factor uses |p|, not |p|^2: r(p) = 1 + k1 |p|^2 + k2 |p|^4."),
    like(lambda c: _project_variant(c, k2_power=2), "k2 multiplies |p|^4, not |p|^2."),
]


register(
    Exercise(
        id="5.5",
        title="Read a BAL problem file",
        name="read_bal",
        kind="code",
        points=2,
        cases=cached(cases_read_bal),
        hints=READ_HINTS,
        fallback=gt_read_bal,
        datasets=("bal",),
        arg_names=("path",),
    ),
    Exercise(
        id="5.6",
        title="The BAL camera: batch projection",
        name="bal_project",
        kind="code",
        points=3,
        cases=cached(cases_bal_project),
        hints=PROJECT_HINTS,
        fallback=gt_project,
        arg_names=("cameras", "points", "cam_idx", "pt_idx"),
    ),
)

