"""Chapter 6, visual-inertial: 6.17 `preintegrate` (IMU pre-integration between keyframes, Forster et al. T-RO 2017).

Oracles: gtsam 4.3.0 `PreintegratedImuMeasurementsManifold` (Forster's on-manifold scheme: its
deltaRij/deltaVij/deltaPij, and `predict`, whose bias correction is the first-order one of Forster's
eq. (44) through the bias Jacobians delRdelBiasOmega etc., which the Python wrapper does not expose) and
exact synthetic ground truth. gtsam's default `PreintegratedImuMeasurements` is the *tangent-space*
variant (GTSAM_TANGENT_PREINTEGRATION): it integrates differently (on this exercise's two windows its deltas
differ from the manifold class's by 0.5e-4–3e-4 over 0.5 s at 1.5 rad/s, 2e-2–3e-2 over 1 s at 4 rad/s, worst of
rad | m/s | m on seeds 0–5), so the manifold class is the oracle of this exercise. The truth case is physical (continuous motion,
exact states), which any consistent integrator reaches to O(dt); it does not single out Forster's scheme. Gravity convention (gtsam `MakeSharedU(9.81)`): the world
z axis points up, g = (0, 0, -9.81) m/s², and the accelerometer measures the specific force
a_m = R_wbᵀ (a_w − g) + b_a + noise (9.81 m/s² upwards at rest); the pre-integrated deltas contain no gravity.
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, like, register
from graders.kit.geometry import skew, so3_exp

G = np.array([0.0, 0.0, -9.81])   # world gravity, z up (gtsam MakeSharedU(9.81))


# ----------------------------------------------------------------- synthetic IMU data

def _body_rate(t, rate, f1, ph1, c):
    """ω(t) (rad/s): a smooth body rate, sinusoids of amplitude `rate` about a constant offset `c`."""
    return rate * np.sin(2 * np.pi * f1 * t + ph1) + c


def imu_window(rng: np.random.Generator, n: int = 100, dt: float = 0.005, rate: float = 1.5, noise: bool = True,
               substeps: int = 32, bias_norms: tuple[float, float] | None = None) -> dict:
    """IMU samples between two keyframes, taken from continuous motion as a real IMU takes them: a smooth
    body rate ω(t) and a smooth world acceleration a_w(t) = 2 sin(2π f₂ t + φ₂) m/s², sampled at t_k = k·dt,
    k = 0 … n−1 (specific force f(t_k) = R(t_k)ᵀ(a_w(t_k) − g)). The true states at T = n·dt are physical, not
    any discrete scheme's: v and p integrate a_w(t) in closed form; R(t) integrates ω(t) by `substeps`
    midpoint steps per sample (a power of 2; error O((dt/substeps)²): ~1e-8 at 200 Hz, 32 substeps). Forster's Euler recursion (which
    holds each sample over its interval) is then O(dt) off the truth, as on a real IMU — about 1e-3 m/s at
    1 kHz, 1e-2 at 200 Hz — and a midpoint scheme (VINS-Mono's) is closer.
    Biases: normal(0, 0.02) rad/s and normal(0, 0.1) m/s² per axis, or of the given norms `bias_norms`
    (|b_g|, |b_a|) in random directions.
    Returns omega_m, acc_m (n, 3) measurements (with biases, and noise if `noise`), dt, the true biases
    and the true states (R, p, v) at the two keyframes."""
    from scipy.spatial.transform import Rotation
    t = np.arange(n) * dt
    f1, f2 = rng.uniform(0.3, 2.0, (2, 3))
    ph1, ph2 = rng.uniform(0, 2 * np.pi, (2, 3))
    c = rng.normal(0, 0.2, 3)
    R0 = Rotation.random(random_state=rng).as_matrix()
    v0 = rng.normal(0, 1.0, 3)
    # R(t) on a fine grid: R(t + h) = R(t) Exp(ω(t + h/2) h); R[k] is the attitude at sample time t_k. The
    # increments of one sample interval are multiplied in order by pairwise halving (substeps a power of 2).
    h = dt / substeps
    t_mid = t[:, None] + (np.arange(substeps) + 0.5) * h                      # (n, m)
    E = so3_exp((_body_rate(t_mid[..., None], rate, f1, ph1, c) * h).reshape(-1, 3)).reshape(n, substeps, 3, 3)
    while E.shape[1] > 1:
        E = E[:, 0::2] @ E[:, 1::2]
    R = [R0]
    for k in range(n):
        R.append(R[-1] @ E[k, 0])
    R = np.array(R)
    omega = _body_rate(t[:, None], rate, f1, ph1, c)
    A, w2, T = 2.0, 2 * np.pi * f2, n * dt
    a_world = A * np.sin(w2 * t[:, None] + ph2)
    f = np.einsum("nji,nj->ni", R[:-1], a_world - G)      # R(t_k)ᵀ (a_w(t_k) − g)
    # a_w is the total world acceleration (gravity included): v(T) = v0 + ∫a_w, p(T) = v0 T + ∫∫a_w, in
    # closed form for the sinusoid.
    v = v0 + A / w2 * (np.cos(ph2) - np.cos(w2 * T + ph2))
    p = v0 * T + A / w2 * (np.cos(ph2) * T - (np.sin(w2 * T + ph2) - np.sin(ph2)) / w2)
    b_g, b_a = rng.normal(0, 0.02, 3), rng.normal(0, 0.1, 3)
    if bias_norms is not None:
        b_g, b_a = (s * b / np.linalg.norm(b) for s, b in zip(bias_norms, (b_g, b_a)))
    sg, sa = (1.7e-3 / np.sqrt(dt), 2.0e-2 / np.sqrt(dt)) if noise else (0.0, 0.0)  # continuous noise densities
    return {"omega_m": omega + b_g + rng.normal(0, 1, (n, 3)) * sg, "acc_m": f + b_a + rng.normal(0, 1, (n, 3)) * sa,
            "dt": dt, "b_g": b_g, "b_a": b_a,
            "truth": {"R_i": R0, "R_j": R[-1], "p_i": np.zeros(3), "p_j": p, "v_i": v0, "v_j": v, "T": T}}


def true_deltas(w: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The deltas the states imply (Forster eq. (33)): ΔR = R_iᵀR_j, Δv = R_iᵀ(v_j − v_i − gΔt),
    Δp = R_iᵀ(p_j − p_i − v_iΔt − ½gΔt²)."""
    s, T = w["truth"], w["truth"]["T"]
    Ri = s["R_i"]
    return (Ri.T @ s["R_j"], Ri.T @ (s["v_j"] - s["v_i"] - G * T),
            Ri.T @ (s["p_j"] - s["p_i"] - s["v_i"] * T - 0.5 * G * T ** 2))


# ----------------------------------------------------------------- oracle (gtsam)

def _gtsam_pim(omega_m, acc_m, dt, b_g, b_a):
    import gtsam

    params = gtsam.PreintegrationParams.MakeSharedU(9.81)
    # The covariances only shape preintMeasCov; the deltas do not depend on them.
    params.setAccelerometerCovariance(np.eye(3) * 4e-4)
    params.setGyroscopeCovariance(np.eye(3) * 3e-6)
    params.setIntegrationCovariance(np.eye(3) * 1e-8)
    pim = gtsam.PreintegratedImuMeasurementsManifold(params, gtsam.imuBias.ConstantBias(b_a, b_g))
    for k in range(len(omega_m)):
        pim.integrateMeasurement(np.asarray(acc_m[k], float), np.asarray(omega_m[k], float), float(dt))
    return pim


def gtsam_deltas(omega_m, acc_m, dt, b_g, b_a):
    pim = _gtsam_pim(omega_m, acc_m, dt, b_g, b_a)
    return pim.deltaRij().matrix(), np.asarray(pim.deltaVij()), np.asarray(pim.deltaPij())


def gtsam_corrected(omega_m, acc_m, dt, b_g, b_a, b_g_new, b_a_new):
    """gtsam's first-order bias-corrected deltas: `predict` from the identity state at rest, minus
    the gravity terms predict adds (v_j = R_iΔv + gΔt, p_j = R_iΔp + ½gΔt²)."""
    import gtsam

    pim = _gtsam_pim(omega_m, acc_m, dt, b_g, b_a)
    T = pim.deltaTij()
    ns = pim.predict(gtsam.NavState(gtsam.Rot3(), np.zeros(3), np.zeros(3)),
                     gtsam.imuBias.ConstantBias(np.asarray(b_a_new, float), np.asarray(b_g_new, float)))
    return ns.attitude().matrix(), np.asarray(ns.velocity()) - G * T, np.asarray(ns.position()) - 0.5 * G * T ** 2


def gtsam_preintegrate(omega_m, acc_m, dt, b_g, b_a):
    """Stand-in for 6.17: gtsam's manifold pre-integration; the bias Jacobians (not exposed by the wrapper)
    by central differences of gtsam's own `predict` (its first-order correction), 1e-4 steps."""
    from scipy.spatial.transform import Rotation
    dR, dv, dp = gtsam_deltas(omega_m, acc_m, dt, b_g, b_a)
    J = np.zeros((9, 6))
    b = np.r_[b_g, b_a]
    h = 1e-4   # predict is linear in δb (v, p) and Exp-linear (R): central differences are exact to ~1e-10
    for c in range(6):
        out = []
        for sgn in (1, -1):
            bb = b.copy()
            bb[c] += sgn * h
            out.append(gtsam_corrected(omega_m, acc_m, dt, b_g, b_a, bb[:3], bb[3:]))
        (Rp, vp, pp), (Rm, vm, pm) = out
        J[0:3, c] = Rotation.from_matrix(dR.T @ Rp).as_rotvec() / (2 * h) - \
            Rotation.from_matrix(dR.T @ Rm).as_rotvec() / (2 * h)
        J[3:6, c], J[6:9, c] = (vp - vm) / (2 * h), (pp - pm) / (2 * h)
    return dR, dv, dp, J


# ----------------------------------------------------------------- hint models (numpy, not the oracle)

def _model(omega_m, acc_m, dt, b_g, b_a, gravity=False, bias=True, order="forster", jr=True):
    """Forster's scheme and the classic slips: gravity removed inside, biases not subtracted, position
    updated with the new velocity. Returns (dR, dv, dp, J)."""
    dR, dv, dp = np.eye(3), np.zeros(3), np.zeros(3)
    J = np.zeros((9, 6))
    for k in range(len(omega_m)):
        w = omega_m[k] - (b_g if bias else 0)
        a = acc_m[k] - (b_a if bias else 0) + (dR.T @ G if gravity else 0)
        Ra, Rax = dR @ a, dR @ skew(a)
        J[6:9, :3] += J[3:6, :3] * dt - 0.5 * Rax @ J[0:3, :3] * dt ** 2
        J[6:9, 3:] += J[3:6, 3:] * dt - 0.5 * dR * dt ** 2
        J[3:6, :3] -= Rax @ J[0:3, :3] * dt
        J[3:6, 3:] -= dR * dt
        E = so3_exp(w * dt)
        Jr = _right_jacobian(w * dt) if jr else np.eye(3)
        J[0:3, :3] = E.T @ J[0:3, :3] - Jr * dt
        if order == "new_velocity":
            dv = dv + Ra * dt
            dp = dp + dv * dt + 0.5 * Ra * dt ** 2
        else:
            dp = dp + dv * dt + 0.5 * Ra * dt ** 2
            dv = dv + Ra * dt
        dR = dR @ E
    return dR, dv, dp, J


def _right_jacobian(phi):
    th = np.linalg.norm(phi)
    S = skew(phi)
    if th < 1e-8:
        return np.eye(3) - 0.5 * S
    return np.eye(3) - (1 - np.cos(th)) / th ** 2 * S + (th - np.sin(th)) / th ** 3 * S @ S


def _correct(out, db_g, db_a):
    dR, dv, dp, J = out
    db = np.r_[db_g, db_a]
    return dR @ so3_exp(J[0:3, :3] @ db_g), dv + J[3:6] @ db, dp + J[6:9] @ db


def numpy_preintegrate(omega_m, acc_m, dt, b_g, b_a):
    """Stand-in for 6.17: the grader's numpy loop of Forster's scheme (gtsam_preintegrate, whose Jacobians come
    from 12 extra gtsam integrations, is the library-backed version the tests hold it to)."""
    return _model(np.asarray(omega_m, float), np.asarray(acc_m, float), float(dt), np.asarray(b_g, float),
                  np.asarray(b_a, float))


# ----------------------------------------------------------------- exercise

def _convert(out, case):
    if not isinstance(out, (tuple, list)) or len(out) != 4:
        raise OutputError("expected a tuple (dR (3, 3), dv (3,), dp (3,), J (9, 6))")
    shapes = [(3, 3), (3,), (3,), (9, 6)]
    arrs = []
    for name, o, s in zip(("dR", "dv", "dp", "J"), out, shapes):
        try:
            a = np.asarray(o, float)
        except (TypeError, ValueError):
            raise OutputError(f"{name}: expected a numeric array of shape {s}") from None
        if a.shape != s or not np.isfinite(a).all():
            raise OutputError(f"{name}: expected a finite array of shape {s}, got shape {a.shape}")
        arrs.append(a)
    return tuple(arrs)


def _delta_error(out, expected):
    """Worst of: rotation angle between the ΔR (rad), ‖Δv error‖ (m/s), ‖Δp error‖ (m)."""
    from scipy.spatial.transform import Rotation
    dR, dv, dp = out[:3]
    eR, ev, ep = expected[:3]
    ang = Rotation.from_matrix(eR.T @ dR if np.allclose(dR @ dR.T, np.eye(3), atol=1e-6) else np.eye(3)).magnitude()
    if not np.allclose(dR @ dR.T, np.eye(3), atol=1e-6):
        ang = np.inf  # not a rotation
    return float(max(ang, np.linalg.norm(dv - ev), np.linalg.norm(dp - ep)))


def _correction_error(out, expected):
    """The learner's first-order correction to the new bias against gtsam's, relative to the size of
    the correction (so a 1 % error in a Jacobian reads 0.01 whatever the window)."""
    oracle, db_g, db_a, uncorrected = expected
    mine = _correct(out, db_g, db_a)
    err = _delta_error(mine, oracle)
    size = _delta_error(uncorrected, oracle)
    return err / max(size, 1e-12)


# 1e-9 (rad, m/s, m): gtsam's manifold scheme and an independent numpy loop agree to ~1e-15 on 100-200
# samples. Every slip below costs >= 1e-5 against gtsam.
TOL_DELTA = 1e-9
# 0.02 (rad, m/s, m) against the physical truth (1 kHz, 0.5 s): Forster's Euler recursion is O(dt) off it,
# 1.5e-3–6.2e-3 over 12 seeds; a midpoint scheme (VINS-Mono's) 0.8e-5–2.1e-5; the semi-implicit order
# (new velocity in Δp) 4.5e-3–6.2e-3. Gravity inside the integration costs ~4.9 and ignoring the biases
# (0.05 rad/s, 0.4 m/s²) 0.14–0.23 (~|b_a|·T).
TOL_TRUTH = 0.02
# 1e-6 relative: a correct Jacobian reproduces gtsam's correction to ~1e-10 (both first order in δb);
# dropping the right Jacobian Jr costs ~1e-3, a missing block 100 %.
TOL_CORRECTION = 1e-6


def cases_preintegrate(rng: np.random.Generator):
    # 1 kHz, 0.5 s: the physical truth, which any consistent integrator of the samples reaches to O(dt) or
    # better; biases of 0.05 rad/s and 0.4 m/s² (consumer-MEMS turn-on biases) so that ignoring them is seen.
    w = imu_window(rng, n=500, dt=0.001, noise=False, bias_norms=(0.05, 0.4))
    args = (w["omega_m"], w["acc_m"], w["dt"], w["b_g"], w["b_a"])
    yield Case("noise-free 1 kHz samples of a continuous motion, true biases given: ΔR, Δv, Δp vs the physical "
               "states (gravity removed); any consistent integration scheme passes",
               args, true_deltas(w), _delta_error, TOL_TRUTH, "rad | m/s | m", convert=_convert, key="truth",
               tags=("truth",))
    for i, (n, rate) in enumerate([(100, 1.5), (200, 4.0)]):
        w = imu_window(rng, n=n, rate=rate)
        b_g_hat = w["b_g"] + rng.normal(0, 0.01, 3)   # the keyframe's bias estimate, not the truth
        b_a_hat = w["b_a"] + rng.normal(0, 0.05, 3)
        args = (w["omega_m"], w["acc_m"], w["dt"], b_g_hat, b_a_hat)
        yield Case(f"window {i + 1} ({n} noisy samples, {rate} rad/s): ΔR, Δv, Δp vs gtsam (manifold)", args,
                   gtsam_deltas(*args), _delta_error, TOL_DELTA, "rad | m/s | m", convert=_convert,
                   key=f"gtsam-{i + 1}", tags=("gtsam",))
        db_g, db_a = rng.normal(0, 0.01, 3), rng.normal(0, 0.05, 3)
        expected = (gtsam_corrected(*args, b_g_hat + db_g, b_a_hat + db_a), db_g, db_a, gtsam_deltas(*args))
        yield Case(f"window {i + 1}: first-order bias correction through J vs gtsam predict", args, expected,
                   _correction_error, TOL_CORRECTION, "rel.", convert=_convert, key=f"correction-{i + 1}",
                   tags=("correction",))


def _delta_case(case) -> bool:
    return "correction" not in case.tags


def _like_delta(model_kw: dict, text: str) -> Hint:
    base = like(lambda c: _model(*c.args, **model_kw), text)

    def when(case, out):
        return _delta_case(case) and base.when(case, out)
    return Hint(text, when)


def _jacobian_slip(**kw):
    def when(case, out):
        if _delta_case(case):
            return False
        J_wrong = _model(*case.args, **kw)[3]
        # the learner's J is that slip's J (1e-6 of its size: the right J differs by ~1e-3 relative)
        return bool(np.abs(out[3] - J_wrong).max() < 1e-6 * np.abs(J_wrong).max())
    return when


HINTS = [
    _like_delta({"gravity": True},
                "your deltas have gravity taken out inside the integration: pre-integrated ΔR, Δv, Δp use the raw "
                "specific force (a_m − b_a) only; gravity enters when the deltas are composed with the states "
                "(v_j = v_i + gΔt + R_iΔv)."),
    _like_delta({"bias": False},
                "your deltas are those of the raw measurements: subtract the bias estimates b_g, b_a from every "
                "sample first."),
    _like_delta({"order": "new_velocity"},
                "your Δp uses the velocity after this sample's update: Δp_{k+1} = Δp_k + Δv_k dt + ½ ΔR_k a_k dt², "
                "with the old Δv_k and ΔR_k."),
    Hint("your rotation-bias Jacobian lacks the right Jacobian J_r(ω dt): ∂ΔR_{k+1}/∂b_g = Exp(ω dt)ᵀ ∂ΔR_k/∂b_g "
         "− J_r(ω dt) dt (Forster et al. 2017, appendix).", _jacobian_slip(jr=False)),
]


register(
    Exercise(
        id="6.17",
        title="IMU pre-integration with first-order bias correction",
        name="preintegrate",
        kind="code",
        points=3,
        cases=cases_preintegrate,
        hints=HINTS,
        fallback=numpy_preintegrate,
        arg_names=("omega_m", "acc_m", "dt", "b_g", "b_a"),
        timeout=20.0,
    ),
)
