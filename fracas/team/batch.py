"""Many TEAM studies that differ only in numbers, run as one compiled computation (sweeps).

Studies that share everything structural (the schedule, the layout and labels, the filter,
the reference) but differ in their a-priori covariances, measurement sigmas and thrust-noise
levels share the reference, the observation matrices H and the augmented transitions Φ_aug;
only P0, R and the process noise Q differ.  :func:`prepare` builds the shared part once;
:func:`batch_noise` evaluates DYNO's Q̃ of every study at once (one ``vmap`` of
:func:`fracas.filters.process_noise.dyno_q` over studies and intervals, on noise partials
computed once); :func:`run_batch` runs the filter scan of :mod:`fracas.team.scan`
(``filter_scan``, unchanged) under ``jax.vmap`` over the studies and returns each study's
final covariances (after its last event), which is what a sweep's table needs.

The noise code takes the front half of :func:`fracas.team.transitions.interval_noise` /
:func:`~fracas.team.transitions.grid_noise` (nodes, partials, cell transitions:
:func:`fracas.team.noise_base.interval_inputs`, :mod:`fracas.team.noise_cells`), the same
functions they call, and runs the sigma- and tau-dependent back half for many studies at once.
Batches are padded to a few sizes (:func:`batch_size`) and schedules to the event buckets
of :func:`fracas.team.transitions.bucket`, so one compile serves many batches.

Core module: arrays in, arrays out; no deck, no file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.filters.process_noise import dyno_q
from fracas.team.gm_exact import (
    augment_noise,
    augment_transitions,
    augmented_P0,
    exact_pieces,
    interval_blocks,
    pad_H,
)
from fracas.team.measure import MeasurementSet, assemble_measurements
from fracas.team.noise_base import bucket, interval_inputs, pad_rows
from fracas.team.noise_cells import cell_inputs, cell_reference, map_cell_noise
from fracas.team.reference import Reference
from fracas.team.scan import filter_scan
from fracas.team.study import Study
from fracas.team.transitions import augmented_transitions
from fracas.team.white_acceleration import white_unit_noise

__all__ = [
    "BatchSetup",
    "prepare",
    "batch_size",
    "batch_noise",
    "batch_R",
    "run_batch",
    "final_covariances",
    "structure_mismatch",
    "prediction_failures",
    "MAX_BATCH",
]

MAX_BATCH = 16  # studies per compiled call (the scan keeps (batch, events, n, n) histories)


def batch_size(b: int) -> int:
    """The padded batch size: 4, 8, 16, 32, ... (a few sizes share compiled code)."""
    return bucket(b, base=4)


@dataclass
class BatchSetup:
    """What a group of studies shares: the structure source ``study``, its reference, its
    measurements (H and the row of every used observation), Φ_aug and (lazily) the noise
    nodes."""

    study: Study
    ref: Reference
    meas: MeasurementSet
    phi_aug: np.ndarray
    _nodes: dict | None = field(default=None, repr=False)
    exact: dict | None = None  # the exact Gauss-Markov model's shared inputs (:func:`_exact_setup`)
    _white: dict = field(default_factory=dict, repr=False)

    @property
    def K(self) -> int:
        return self.study.schedule.n


def prepare(study: Study, ref: Reference) -> BatchSetup:
    """The shared part of a group (PHI propagation, built-in gains, no guidance events:
    a guidance event feeds its execution errors back into the filter, which the batched
    scan does not do; such studies run one by one)."""
    if study.propagation != "phi" or study.filter_kind == "user" or study.guidance or study.resets:
        raise ValueError("batched studies need PHI propagation, a built-in gain, no guidance and no reset events")
    meas = assemble_measurements(study, ref)
    phi = augmented_transitions(study, ref)
    if study.noise_model == "exact" and study.has_noise:
        if study.gencov and not np.array_equal(study.noise_tau_assumed, study.noise_tau_true):
            raise ValueError("batched exact Gauss-Markov studies need equal assumed and true tau")
        ex = _exact_setup(study, ref)
        phi = augment_transitions(phi, ex["gamma"], ex["E"], study.nx)
        return BatchSetup(study, ref, meas, phi, exact=ex)
    return BatchSetup(study, ref, meas, phi)


def _exact_setup(study: Study, ref: Reference) -> dict:
    """The exact model's shared part (fracas.team.gm_exact): Gamma and E (they depend on tau
    only) and the noise Q of each component at unit sigma, (3, K, nx + 3, nx + 3): a study's
    Q is sum_i sigma_i^2 Q_i (the components are independent)."""
    t = np.asarray(ref.times_s, np.float64)
    pc = exact_pieces(study, t, np.asarray(ref.states)[0], ref.states, ref.primary)  # one integration
    tau = study.noise_tau_assumed
    gamma, E, _ = interval_blocks(pc, np.zeros(3), tau)
    units = [interval_blocks(pc, np.eye(3)[i], tau)[2] for i in range(3)]
    return {"gamma": gamma, "E": E, "Q_unit": np.array(units)}


def structure_mismatch(a: Study, b: Study) -> str | None:
    """None when ``b`` has the same structure as ``a`` (everything but the numbers a batch
    varies: P0, noise sigma/tau, observation and true sigmas); else what differs."""
    sa, sb = a.schedule, b.schedule
    checks = [
        ("schedule times", sa.n == sb.n and np.array_equal(sa.times_s, sb.times_s)),
        ("schedule events", sa.events == sb.events and sa.tracking == sb.tracking),
        (
            "predictions",
            {k: list(v) for k, v in sa.predict_to_s.items()} == {k: list(v) for k, v in sb.predict_to_s.items()},
        ),
        ("layout", a.layout == b.layout and a.labels == b.labels and a.roles == b.roles),
        ("dynamic", np.array_equal(a.dynamic, b.dynamic)),
        ("filter", (a.filter_kind, a.square_root, a.gencov) == (b.filter_kind, b.square_root, b.gencov)),
        (
            "propagation",
            (a.propagation, a.noise_model, a.noise_step_s) == (b.propagation, b.noise_model, b.noise_step_s),
        ),
        (
            "trajectory",
            (a.trajectory_hash, a.start_s, a.stop_s, a.thrust_switches_s)
            == (b.trajectory_hash, b.start_s, b.stop_s, b.thrust_switches_s),
        ),
        ("elevation", a.min_elevation_deg == b.min_elevation_deg),
        (
            "tracking",
            [(t.kind, t.stations, t.body) for t in a.tracking] == [(t.kind, t.stations, t.body) for t in b.tracking],
        ),
        (
            "stars",
            all(
                (x.star_unit is None) == (y.star_unit is None)
                and (x.star_unit is None or np.array_equal(x.star_unit, y.star_unit))
                for x, y in zip(a.tracking, b.tracking)
            ),
        ),
        (  # onboard sensor settings and beacon cones shape H and the schedule: not batchable numbers
            "observations",
            [(o.kind, o.stations, o.sensor, o.visibility) for o in a.observations]
            == [(o.kind, o.stations, o.sensor, o.visibility) for o in b.observations],
        ),
        ("stations", a.stations == b.stations),
        ("shapes", a.P0_assumed.shape == b.P0_assumed.shape and a.true_sigma.shape == b.true_sigma.shape),
        (  # the exact Gauss-Markov model: Gamma and E depend on tau (fracas.team.gm_exact)
            "noise correlation times",
            a.noise_model != "exact"
            or (
                np.array_equal(a.noise_tau_assumed, b.noise_tau_assumed)
                and np.array_equal(a.noise_tau_true, b.noise_tau_true)
                and a.has_noise == b.has_noise
                and a.P0_noise_states is None
                and b.P0_noise_states is None
            ),
        ),
        ("user gain", a.user_gain is None and b.user_gain is None),
    ]
    bad = [name for name, ok in checks if not ok]
    return ", ".join(bad) if bad else None


def prediction_failures(study: Study, ref: Reference) -> list[tuple[int, float]]:
    """(k, t_to) of every prediction event whose integration runs off the trajectory (a
    property of the reference, the same for every study of a group)."""
    from fracas.team.predict import predict_from

    if not study.schedule.predict_to_s:
        return []
    n, K = study.layout.n, study.schedule.n
    res = SimpleNamespace(
        study=study, ref=ref, times_s=study.schedule.times_s, Pa_plus=np.zeros((K, n, n)), Pt_plus=None
    )
    out = []
    for k, targets in study.schedule.predict_to_s.items():
        for t in targets:
            if int(predict_from(res, k, t)[2]):
                out.append((k, t))
    return out


# ----------------------------------------------------------------------------- process noise
@jax.jit
def _dyno_studies(phi, h0, h1, sigma, tau, dt):
    """DYNO's Q̃ (S, M, nx, nx) of S noise levels (sigma, tau (S, 3)) over M intervals."""
    per_interval = jax.vmap(dyno_q, in_axes=(0, 0, 0, None, None, 0))
    return jax.vmap(per_interval, in_axes=(None, None, None, 0, 0, None))(phi, h0, h1, sigma, tau, dt)


def _interval_nodes(study: Study, ref: Reference) -> dict:
    """interval_noise's partials, nodes and transitions (the part that needs no sigma):
    :func:`fracas.team.noise_base.interval_inputs`, shared with it."""
    m, args = interval_inputs(study, ref.times_s, ref.states, ref.primary, ref.phi)
    return {"model": "interval", "m": m, "args": args}


def _grid_nodes(study: Study, ref: Reference) -> dict:
    """grid_noise's cells, partials and cell transitions (the part that needs no sigma):
    :func:`fracas.team.transitions.cell_reference` and ``cell_inputs``, shared with it."""
    t = np.asarray(ref.times_s, dtype=np.float64)
    ci = cell_inputs(study, t, *cell_reference(study, t, ref.states[0], getattr(ref, "product", None)))
    nc = ci["nc"]
    mp = bucket(nc)
    ci.update(model="grid", m=nc, args=tuple(pad_rows(ci[k], mp) for k in ("phic", "h0", "h1", "dt")))
    return ci


def _nodes(setup: BatchSetup) -> dict:
    if setup._nodes is None:
        st = setup.study
        setup._nodes = _interval_nodes(st, setup.ref) if st.noise_model == "interval" else _grid_nodes(st, setup.ref)
    return setup._nodes


def batch_noise(setup: BatchSetup, studies: list[Study]) -> tuple[np.ndarray, np.ndarray]:
    """Qa, Qt (B, K, nx, nx): the process noise of every study (the model of
    :func:`fracas.team.transitions.process_noise`), assumed and true."""
    B, K, nx = len(studies), setup.K, setup.study.nx
    Qa, Qt = np.zeros((B, K, nx, nx)), np.zeros((B, K, nx, nx))
    if K >= 2:
        _add_white(setup, studies, Qa, Qt)
    if setup.exact is not None:  # full size: sum_i sigma_i^2 Q_i on [x, eta], white on x
        n = setup.study.layout.n
        qu = setup.exact["Q_unit"]
        out = []
        for Qw, which in ((Qa, "assumed"), (Qt, "true")):
            sig = np.array([getattr(s, f"noise_sigma_{which}") if s.gencov else s.noise_sigma_assumed for s in studies])
            gm = np.einsum("bi,ikpq->bkpq", sig**2, qu)
            out.append(np.array([augment_noise(gm[b], Qw[b], n) for b in range(B)]))
        return out[0], out[1]
    noisy = [i for i, s in enumerate(studies) if s.has_noise]
    if not noisy or K < 2:
        return Qa, Qt
    nd = _nodes(setup)
    sig = np.array(
        [s.noise_sigma_assumed for s in (studies[i] for i in noisy)] + [studies[i].noise_sigma_true for i in noisy]
    )
    tau = np.array(
        [s.noise_tau_assumed for s in (studies[i] for i in noisy)] + [studies[i].noise_tau_true for i in noisy]
    )
    S, Sp = len(sig), batch_size(len(sig))
    sig = np.concatenate([sig, np.repeat(sig[-1:], Sp - S, axis=0)])
    tau = np.concatenate([tau, np.repeat(tau[-1:], Sp - S, axis=0)])
    phi, h0, h1, dt = nd["args"]
    q = np.asarray(_dyno_studies(*(jnp.asarray(a) for a in (phi, h0, h1, sig, tau, dt))))[:S, : nd["m"]]
    idx = np.array(noisy)
    if nd["model"] == "interval":
        Q = np.concatenate([np.zeros((S, 1, nx, nx)), q], axis=1)
    else:
        Q = map_cell_noise(nd, q, K)
    n = len(noisy)
    Qa[idx] += Q[:n]
    Qt[idx] += Q[n:]
    return Qa, Qt


def _add_white(setup: BatchSetup, studies: list[Study], Qa: np.ndarray, Qt: np.ndarray) -> None:
    """Add every study's white-acceleration noise (q times the unit-density noise of its
    direction, :func:`fracas.team.transitions.white_unit_noise`, computed once per direction
    and quadrature step for the group) to Qa, Qt in place."""
    t = np.asarray(setup.ref.times_s, dtype=np.float64)
    for i, s in enumerate(studies):
        if not s.has_white_noise:
            continue
        true = (s.white_q_true, s.white_direction_true) if s.gencov else (s.white_q_assumed, s.white_direction_assumed)
        for Q, (q, d) in ((Qa, (s.white_q_assumed, s.white_direction_assumed)), (Qt, true)):
            if q <= 0:
                continue
            key = (d, float(s.white_step_s))
            if key not in setup._white:
                setup._white[key] = white_unit_noise(s, t, setup.ref.states[0], [d])[d]
            Q[i] += q * setup._white[key]


def batch_R(setup: BatchSetup, studies: list[Study]) -> tuple[np.ndarray, np.ndarray]:
    """Ra, Rt (B, K, m, m): every study's assumed and true measurement noise on the group's
    observation rows (MENO: diag(sigma²), unit on the padded rows)."""
    meas = setup.meas
    B = len(studies)
    Ra = np.broadcast_to(meas.R_assumed, (B,) + meas.R_assumed.shape).copy()
    Rt = np.broadcast_to(meas.R_true, (B,) + meas.R_true.shape).copy()
    used = [r for r in meas.records if r.used]
    if not used:
        return Ra, Rt
    kk = np.array([r.k for r in used], dtype=np.intp)
    rr = np.array([r.row for r in used], dtype=np.intp)
    jj = np.array([r.tracking for r in used], dtype=np.intp)
    for b, s in enumerate(studies):
        obs_sig = np.array([o.sigma for o in s.observations], dtype=np.float64)
        Ra[b, kk, rr, rr] = obs_sig[jj] ** 2
        Rt[b, kk, rr, rr] = s.true_sigma[jj] ** 2
    return Ra, Rt


# ----------------------------------------------------------------------------- the batched filter
@partial(jax.jit, static_argnames=("layout", "kind", "gencov", "square_root"))
def _final(P0a, P0t, phi, Qa, Qt, H, Ra, Rt, last, *, layout, kind, gencov, square_root):
    """vmap of the filter scan over studies (shared Φ and H); each study's P⁺ at event ``last``."""

    def one(p0a, p0t, qa, qt, ra, rt):
        outs = filter_scan(
            p0a, p0t, phi, qa, qt, H, ra, rt, layout=layout, kind=kind, gencov=gencov, square_root=square_root
        )
        return outs[1][last], outs[3][last]

    return jax.vmap(one)(P0a, P0t, Qa, Qt, Ra, Rt)


def _pad_events(a: np.ndarray, Kp: int, eye: bool) -> np.ndarray:
    """Neutral events (identity Φ / unit R, else zero) appended on axis -3 up to Kp
    (fracas.team.scan's padding, for batched arrays)."""
    K = a.shape[-3]
    if K == Kp:
        return a
    extra = np.zeros(a.shape[:-3] + (Kp - K,) + a.shape[-2:])
    if eye:
        extra[...] = np.eye(a.shape[-1])
    return np.concatenate([a, extra], axis=-3)


def run_batch(setup: BatchSetup, P0a, P0t, Qa, Qt, Ra, Rt, pad_to: int = 1) -> tuple[np.ndarray, np.ndarray | None]:
    """The filter over the group's schedule for B studies at once (padded to
    :func:`batch_size` of max(B, ``pad_to``): the last study repeated); (Pa_plus, Pt_plus or
    None) (B, n, n) after the last event."""
    st = setup.study
    B, K = len(P0a), setup.K
    Kp, Bp = bucket(K), batch_size(max(B, pad_to))

    def pad_b(a):
        a = np.asarray(a, dtype=np.float64)
        return np.concatenate([a, np.repeat(a[-1:], Bp - B, axis=0)]) if Bp > B else a

    args = [
        pad_b(P0a),
        pad_b(P0t),
        _pad_events(setup.phi_aug, Kp, True),
        pad_b(_pad_events(Qa, Kp, False)),
        pad_b(_pad_events(Qt, Kp, False)),
        _pad_events(setup.meas.H if setup.exact is None else pad_H(setup.meas.H), Kp, False),
        pad_b(_pad_events(Ra, Kp, True)),
        pad_b(_pad_events(Rt, Kp, True)),
    ]
    Pa, Pt = _final(
        *(jnp.asarray(a) for a in args),
        jnp.asarray(K - 1),
        layout=st.layout if setup.exact is None else st.layout._replace(nw=st.layout.nw + 3),
        kind=st.filter_kind,
        gencov=st.gencov,
        square_root=st.square_root,
    )
    Pa = np.asarray(Pa)[:B]
    return Pa, (np.asarray(Pt)[:B] if st.gencov else None)


def final_covariances(
    setup: BatchSetup, studies: list[Study], max_batch: int = MAX_BATCH, pad_to: int = 1
) -> tuple[np.ndarray, np.ndarray | None]:
    """Every study's final assumed (and true) covariance (B, n, n), in calls of at most
    ``max_batch`` studies, each padded to at least ``pad_to`` (one compile for a group's
    chunks).  Each study must have the setup's structure
    (:func:`structure_mismatch`)."""
    outs_a, outs_t = [], []
    for i in range(0, len(studies), max_batch):
        part = studies[i : i + max_batch]
        Qa, Qt = batch_noise(setup, part)
        Ra, Rt = batch_R(setup, part)
        if setup.exact is not None:  # the noise states appended (stationary, or punched)
            P0a = np.array([augmented_P0(s, 0) for s in part])
            P0t = np.array([augmented_P0(s, 1) for s in part])
        else:
            P0a = np.array([s.P0_assumed for s in part])
            P0t = np.array([s.P0_true for s in part])
        Pa, Pt = run_batch(setup, P0a, P0t, Qa, Qt, Ra, Rt, pad_to=min(pad_to, max_batch))
        outs_a.append(Pa)
        outs_t.append(Pt)
    Pa = np.concatenate(outs_a)
    Pt = None if outs_t[0] is None else np.concatenate(outs_t)
    return Pa, Pt
