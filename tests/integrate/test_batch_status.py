"""A batch in which some members fail: each member reports its own status and the healthy
members' results are those they have without the failures.

Batch: six LEO propagations (the model, parameters and states of ``test_batch``), in chunks of
four rows (members 0-3, then 4, 5 and two padding rows):

* member 1 starts from a non-finite state (NaN in x0)            -> ``RunStatus.NONFINITE``;
* member 2 hits ``max_steps``.  ``max_steps`` is one value for the whole batch (the integrator
  settings are shared by its members), so the model gets ``max_steps = 400`` -- the healthy
  members take ~130 steps to the final time -- and member 2 starts on a circular orbit of
  radius 2000 km, whose nominal step (c_nom r^1.5 / sqrt(mu), ~7 s instead of ~46 s) needs
  ~870 steps: it stops at step 400                                -> ``RunStatus.MAX_STEPS``;
* members 0, 3, 4, 5 are nominal                                  -> ``RunStatus.OK``.

References, for every healthy member:

1. an independent single run, ``propagate`` (or ``propagate_with_sensitivities``) of that
   member alone: equal to 1e-12 relative (position, velocity and mass norms; as in
   ``test_batch``: the vmapped program may fuse and round differently from the single one),
   step counts, rectifications and output times exactly;
2. the same batch with the two failing members replaced by nominal states: bit for bit (0
   tolerance).  It is the same executable on the same shapes, and the lanes of a vmapped
   while loop are independent (a finished lane is frozen by a select), so a failing lane --
   NaN arithmetic, or a loop kept running up to ``max_steps`` -- must not change a bit of the
   others.

The failed members' status equals that of their own single run, too.
"""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from fracas.integrate.batch import host_devices, propagate_batch
from fracas.integrate.propagate import propagate, propagate_with_sensitivities
from fracas.io.trajectory_file import STATUS_TEXT as FILE_STATUS_TEXT
from fracas.io.trajectory_file import read_trajectory_file, write_trajectory_file
from fracas.status import (
    PROPAGATION_STATUSES,
    STATUS_TEXT,
    RunStatus,
    batch_status_summary,
    format_status_summary,
    status_text,
)
from tests.integrate.test_batch import MODEL, PARAMS, T_OUT, _close_states, _states

MAX_STEPS = 400
MODEL_CAPPED = dataclasses.replace(MODEL, integrator=dataclasses.replace(MODEL.integrator, max_steps=MAX_STEPS))
NAN_MEMBER, SLOW_MEMBER = 1, 2
HEALTHY = (0, 3, 4, 5)
LABELS = ("mu[earth]",)
_R_SLOW = 2000.0  # km: circular, nominal step ~7 s


def _batch_states():
    """(x0s with the two failing members, the same with nominal states in their place)."""
    clean = _states(6, seed=11)
    x0s = clean.copy()
    x0s[NAN_MEMBER, 0] = np.nan
    x0s[SLOW_MEMBER] = [_R_SLOW, 0.0, 0.0, 0.0, np.sqrt(398600.4418 / _R_SLOW), 0.0, 1000.0]
    return x0s, clean


def _run(x0s, sens: bool):
    return propagate_batch(
        MODEL_CAPPED,
        PARAMS,
        None,
        0.0,
        x0s,
        T_OUT,
        chunk_size=4,
        with_sensitivities=sens,
        param_labels=LABELS if sens else (),
        devices=host_devices()[:1],
    )


def _check_statuses(tr, singles):
    assert RunStatus(int(tr.status[NAN_MEMBER])) is RunStatus.NONFINITE
    assert RunStatus(int(tr.status[SLOW_MEMBER])) is RunStatus.MAX_STEPS
    assert int(tr.n_steps[SLOW_MEMBER]) == MAX_STEPS
    for i in HEALTHY:
        assert RunStatus(int(tr.status[i])) is RunStatus.OK
    for i, one in singles.items():  # every member, failed ones included, as when run alone
        assert int(tr.status[i]) == int(one.status)
    assert batch_status_summary(tr.status) == {RunStatus.OK: 4, RunStatus.MAX_STEPS: 1, RunStatus.NONFINITE: 1}
    assert not np.isfinite(tr.x_final[NAN_MEMBER]).any()
    assert np.isnan(tr.x[NAN_MEMBER, 1:]).all()  # t_out[0] is reached without a step (state as given)
    # the capped member: outputs it reached are finite, the rest NaN, as in its single run
    np.testing.assert_array_equal(np.isnan(tr.t[SLOW_MEMBER]), np.isnan(np.asarray(singles[SLOW_MEMBER].t)))


def _check_healthy_against_single(tr, singles):
    for i in HEALTHY:
        one = singles[i]
        _close_states(tr.x[i], one.x)
        _close_states(tr.x_final[i], one.x_final)
        np.testing.assert_array_equal(tr.t[i], np.asarray(one.t))
        assert int(tr.n_steps[i]) == int(one.n_steps)
        assert int(tr.n_rect[i]) == int(one.n_rect)


def _assert_rows_identical(a, b, rows):
    """Every field of the namedtuples ``a`` and ``b`` (numpy, batch axis first), bit for bit."""
    for name, fa, fb in zip(a._fields, a, b):
        np.testing.assert_array_equal(np.asarray(fa)[list(rows)], np.asarray(fb)[list(rows)], err_msg=name)


def test_failed_members_do_not_touch_the_others():
    x0s, clean = _batch_states()
    tr = _run(x0s, sens=False)
    singles = {i: propagate(MODEL_CAPPED, PARAMS, None, 0.0, x0s[i], T_OUT) for i in range(len(x0s))}
    _check_statuses(tr, singles)
    _check_healthy_against_single(tr, singles)
    ref = _run(clean, sens=False)
    assert (ref.status == 0).all()
    _assert_rows_identical(tr, ref, HEALTHY)


@pytest.mark.slow  # the batched AD program (~50 s cold); the plain batch case stays in make test
def test_failed_members_do_not_touch_the_others_with_sensitivities():
    x0s, clean = _batch_states()
    tr, sens = _run(x0s, sens=True)
    singles = {}
    single_sens = {}
    for i in range(len(x0s)):
        singles[i], single_sens[i] = propagate_with_sensitivities(
            MODEL_CAPPED, PARAMS, None, 0.0, x0s[i], T_OUT, LABELS
        )
    _check_statuses(tr, singles)
    _check_healthy_against_single(tr, singles)
    for i in HEALTHY:
        for a, b in ((sens.stm[i], single_sens[i].stm), (sens.par[i], single_sens[i].par)):
            b = np.asarray(b)
            assert np.all(np.isfinite(a))
            assert np.max(np.abs(a - b)) <= 1e-11 * np.max(np.abs(b))  # as test_batch
    assert np.isnan(sens.stm[NAN_MEMBER, 1:]).all()
    ref, ref_sens = _run(clean, sens=True)
    _assert_rows_identical(tr, ref, HEALTHY)
    _assert_rows_identical(sens, ref_sens, HEALTHY)


def test_a_failed_last_row_padding_the_chunk():
    """The last chunk is padded with copies of its last row: here a NaN row (no effect)."""
    x0s, clean = _batch_states()
    x0s = x0s[[0, 3, 4, 5, 1]]  # chunks (0, 3, 4, 5) and (1, pad, pad, pad)
    tr = _run(x0s, sens=False)
    ref = _run(clean[[0, 3, 4, 5, 4]], sens=False)
    _assert_rows_identical(tr, ref, range(4))
    assert [RunStatus(int(s)) for s in tr.status] == [RunStatus.OK] * 4 + [RunStatus.NONFINITE]


# ------------------------------------------------------------------------ the enumeration
def test_run_status_codes_and_texts():
    assert [int(s) for s in PROPAGATION_STATUSES] == [0, 1, 2, 3]
    assert {s.name: int(s) for s in RunStatus} == {
        "OK": 0,
        "STOPPED": 1,
        "MAX_STEPS": 2,
        "NONFINITE": 3,
        "OUTSIDE_TRAJECTORY": 5,
        "NOT_POSITIVE_DEFINITE": 6,
        "NONFINITE_COVARIANCE": 7,
    }
    # the texts trajectory files have always carried
    assert STATUS_TEXT[0] == "reached the final time"
    assert STATUS_TEXT[1] == "stop condition met"
    assert STATUS_TEXT[2] == "maximum number of steps reached"
    assert STATUS_TEXT[3] == "non-finite state or step below eps_t"
    assert STATUS_TEXT == {int(s): s.text for s in RunStatus} and FILE_STATUS_TEXT is STATUS_TEXT
    assert all(type(k) is int for k in STATUS_TEXT)
    assert [s for s in RunStatus if s.ok] == [RunStatus.OK, RunStatus.STOPPED]
    assert status_text(np.int32(2)) == RunStatus.MAX_STEPS.text
    assert status_text(4) == "unknown status 4" and status_text(-1) == "unknown status -1"
    assert batch_status_summary([]) == {}
    summary = batch_status_summary(np.array([3, 0, 0, 9, 0]))
    assert summary == {RunStatus.OK: 3, RunStatus.NONFINITE: 1, 9: 1}
    assert list(summary) == [0, 3, 9] and type(list(summary)[2]) is int
    assert (
        format_status_summary(summary)
        == "3 reached the final time, 1 non-finite state or step below eps_t, 1 unknown status 9"
    )


@pytest.mark.parametrize("code", [int(s) for s in RunStatus] + [4])
def test_run_status_texts_are_what_the_trajectory_file_writes(tmp_path, code):
    from tests.io.test_trajectory_file import _data

    data = _data(sens=False)
    data.status = code
    path = write_trajectory_file(tmp_path / "t.h5", data)
    back = read_trajectory_file(path)
    assert back.status == code
    assert back.status_text == status_text(code) == back.summary_dict()["status_text"]
    with h5py.File(path, "r") as f:
        meaning = f["trajectory/status"].attrs["meaning"]
    meaning = meaning.decode() if isinstance(meaning, bytes) else str(meaning)
    # "0 reached the final time; 1 stop condition met; ..." : the propagation codes, unchanged
    assert meaning == "; ".join(f"{int(s)} {s.text}" for s in PROPAGATION_STATUSES)
    assert meaning == (
        "0 reached the final time; 1 stop condition met; 2 maximum number of steps reached; "
        "3 non-finite state or step below eps_t"
    )
