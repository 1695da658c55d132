"""The compiled refresh against the Python pipeline: the same streams, side by side.

Each test feeds a :class:`~rhmpc.control.reference.PredictedReference` and its compiled twin
(:mod:`rhmpc.control.compiled_reference`) the same samples through the same calls and compares,
after every refresh, the placed points of the ticks it covers, within ``RTOL`` = 1e-9 of the
signal's range (or of the points' own size where they are larger): the two sum their products
in different orders, nothing else. The event counters must be equal at every refresh; the
running forecast-error RMS per lead (``RTOL`` relative), the mean sample age, the gate's floor
and state every ``STATE_EVERY`` refreshes and at the end.

The streams come from a seeded generator: a quasi-periodic motion with noise, dropouts (NaN
rows and None), gaps of 1 … 5 rows and a long one, isolated 3-mm outliers, a lasting 4-mm step,
a 0.5-m sample, and a sensor latency that grows during the run.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from predictors import make_predictor
from predictors.rls_one_step import OneStepRLS
from rhmpc.control import compiled_reference as cr
from rhmpc.control.reference import PredictedReference

if cr.load_library() is None:
    pytest.skip(f"no compiled refresh: {cr.unavailable_reason}", allow_module_level=True)

TS, DS, N = 0.5e-3, 15, 50
DT = DS * TS
ORIGIN = np.array([0.1, -0.2, 0.3])
RTOL = 1e-9
STATE_EVERY = 97
#: Ticks from a pipelined refresh's update to its interpolation (sim.loop.closed_loop).
LAG = 3


def motion(rng: np.random.Generator, n: int, d: int, noise: float = 2e-5) -> np.ndarray:
    """(n, d) heart-like motion at the predictor's period [m]: three harmonics of a rate that
    drifts around 1.2 Hz, a slow breathing term, white noise."""
    t = np.arange(n) * DT
    phase = 2 * np.pi * np.cumsum(1.2 + 0.1 * np.sin(2 * np.pi * 0.1 * t)) * DT
    amp = rng.uniform(1e-3, 4e-3, (3, d))
    shift = rng.uniform(0.0, 2 * np.pi, (3, d))
    z = sum(amp[h] * np.sin((h + 1) * phase[:, None] + shift[h]) for h in range(3))
    z = z + 1e-3 * np.sin(2 * np.pi * 0.25 * t)[:, None]
    return z + rng.normal(0.0, noise, z.shape)


def with_events(rng: np.random.Generator, z: np.ndarray) -> list:
    """The samples of ``z`` with dropouts, gaps, outliers, a step, a 0.5-m sample and one whose
    square overflows."""
    n, d = z.shape
    samples: list = list(z.copy())
    for k in rng.choice(np.arange(200, n), n // 40, replace=False):
        samples[k] = None if rng.random() < 0.5 else np.full(d, np.nan)
    for gap in (1, 2, 3, 4, 5, 40):
        k0 = int(rng.integers(300, n - 50))
        samples[k0 : k0 + gap] = [None] * gap
    for k in rng.choice(np.arange(n // 2, n), 8, replace=False):  # isolated outliers
        if samples[k] is not None:
            samples[k] = samples[k] + rng.choice([-3e-3, 3e-3])
    for k in range(int(0.7 * n), n):  # a lasting step: the gate unlocks
        if samples[k] is not None:
            samples[k] = samples[k] + 4e-3
    samples[int(0.85 * n)] = np.full(d, 0.5)  # the gate rejects it, else the guard trips
    samples[int(0.9 * n)] = np.full(d, 1e200)  # finite, its square is not: missing
    return samples


def stamp(k: int, n: int) -> float:
    """Measurement time of sample k [s]: the latency grows from 0 to 20 ms, then to 50 ms."""
    lag = 0 if k < n // 3 else 40 if k < 2 * n // 3 else 100
    return (k * DS - lag) * TS


class Twins:
    """A Python reference and its compiled twin, fed the same calls and compared."""

    def __init__(self, name: str, d: int, *, gate=0.0, correlated: bool = True,
                 guard_speed: float = 0.3, give_dim: bool = True, place: bool = True,
                 settings_dim: int | None = None, scale: float = 1e-2, constants=(),
                 **settings) -> None:
        pred = make_predictor(name, dt=DT, unit=1.0, correlated=correlated, dim=settings_dim,
                              **settings)
        for constant, value in constants:  # class constants of Predictor, set on the instance
            setattr(pred, constant, value)
        self.python = PredictedReference(pred, TS, N, DS, outlier_gate=gate, max_rejections=3,
                                         gate_calibration=100, guard_speed=guard_speed)
        self.compiled, why = cr.compile_reference(self.python, dim=d if give_dim else None)
        assert self.compiled is not None, why
        assert why == ""
        self.both = (self.python, self.compiled)
        if place:
            for r in self.both:
                r.place(ORIGIN)
        self.placed, self.scale, self.worst, self.refreshes = place, scale, 0.0, 0

    def call(self, method: str, *args) -> None:
        for r in self.both:
            getattr(r, method)(*args)

    def pipelined(self, tick: int, z, t: float) -> None:
        """The slices of one refresh, in the order of a pipelined loop, then the checks."""
        for method, args in (("update", (tick, z, t)), ("learn", ()), ("predict", ()),
                             ("interpolate", ()), ("score", ())):
            self.call(method, *args)
        self.check(tick + LAG)

    def refresh(self, tick: int, z, t: float) -> None:
        self.call("refresh", tick, z, t)
        self.check(tick)

    def check(self, tick: int, count: int = DS) -> None:
        """The points of ticks tick … tick + count − 1 and the counters; the rest of the state
        every STATE_EVERY refreshes."""
        a, b = (r.horizons(tick, count) for r in self.both)
        assert (a is None) == (b is None)
        if a is not None:
            assert a.shape == b.shape == (count, N, 3 if self.placed else a.shape[2])
            centred = a - ORIGIN[: a.shape[2]] if self.placed else a
            size = max(self.scale, float(np.abs(centred).max()))
            self.worst = max(self.worst, float(np.abs(a - b).max()) / size)
            assert self.worst <= RTOL, (tick, self.worst)
        assert dict(self.python.predictor.counts) == dict(self.compiled.predictor.counts), tick
        assert self.python.locked == self.compiled.locked
        self.refreshes += 1
        if self.refreshes % STATE_EVERY == 0:
            self.check_state()

    def check_state(self) -> None:
        """Forecast-error RMS (it runs the pending score, on both), sample age, gate, flags."""
        py, c = self.python, self.compiled
        np.testing.assert_allclose(c.predictor.forecast_error_rms,
                                   py.predictor.forecast_error_rms, rtol=RTOL, atol=0)
        assert c.age_count == py.age_count
        np.testing.assert_allclose(c.mean_age, py.mean_age, rtol=1e-12)
        assert (py.gate is None) == (c.gate is None)
        if py.gate is not None:
            assert (py.gate.floor is None) == (c.gate.floor is None)
            if py.gate.floor is not None:
                assert c.gate.floor == pytest.approx(py.gate.floor, rel=RTOL)
            assert c.gate.locked == py.gate.locked
        assert c.predictor.ready == py.predictor.ready and c.predictor.d == py.predictor.d


def feed(twins: Twins, samples: list, pipelined: bool = True) -> Twins:
    n = len(samples)
    for k, z in enumerate(samples):
        (twins.pipelined if pipelined else twins.refresh)(k * DS, z, stamp(k, n))
    twins.check_state()
    return twins


@pytest.mark.parametrize("gate", [0.0, 1e-3, None], ids=["gate-off", "gate-fixed", "calibrated"])
@pytest.mark.parametrize("d", [1, 3])
@pytest.mark.parametrize("correlated", [True, False], ids=["correlated", "independent"])
@pytest.mark.parametrize("name", ["generalized", "one-step"])
def test_pipelined_slices_make_the_points_of_the_python_pipeline(name, correlated, d, gate):
    rng = np.random.default_rng(11)
    z = motion(rng, 2000, d)
    twins = feed(Twins(name, d, gate=gate, correlated=correlated, scale=float(np.ptp(z))),
                 with_events(rng, z))
    counts = twins.python.predictor.counts
    assert counts["missing"] > 100  # the events happened
    if gate == 0.0:
        assert counts["reference_guard"] >= 1
    else:
        assert counts["outliers_rejected"] >= 5 and counts["gate_unlocked"] >= 1
        assert twins.compiled.gate.floor is not None  # the calibration finished
    assert twins.compiled.mean_age > 0.02  # the latency grew
    print(f"{name} {'correlated' if correlated else 'independent'} d={d} gate={gate}: "
          f"worst {twins.worst:.1e}")


@pytest.mark.parametrize("init", ["hold", "zeros"])
@pytest.mark.parametrize("gate", [0.0, 1e-3, None], ids=["gate-off", "gate-fixed", "calibrated"])
@pytest.mark.parametrize("name", ["generalized", "one-step"])
def test_whole_refreshes_make_the_points_of_the_python_pipeline(name, gate, init):
    rng = np.random.default_rng(12)
    z = motion(rng, 2000, 3)
    twins = feed(Twins(name, 3, gate=gate, init=init, scale=float(np.ptp(z))),
                 with_events(rng, z), pipelined=False)
    assert twins.python.predictor.counts["missing"] > 100
    print(f"{name} refresh() gate={gate} init={init}: worst {twins.worst:.1e}")


@pytest.mark.parametrize("correlated", [True, False], ids=["correlated", "independent"])
@pytest.mark.parametrize("name", ["generalized", "one-step"])
def test_the_range_guard_and_the_covariance_bound_act_alike(name, correlated):
    """The predictor's guards made to act often: forecasts clipped to the recent range itself
    (G = 0.05) over a window of 0.3 s, through dropouts and a gap longer than the window; an axis
    that hardly moves (its range floored at 10 % of the widest); P bounded at P₀
    (``p_max_factor`` 1: the wind-up of the directions it leaves unexcited in the correlated
    problem is cut at once)."""
    rng = np.random.default_rng(21)
    z = motion(rng, 2000, 3)
    z[:, 2] *= 0.02
    samples = with_events(rng, z)
    for k in rng.choice(np.arange(100, 2000), 300, replace=False):
        samples[k] = None
    samples[1200:1260] = [None] * 60
    twins = Twins(name, 3, correlated=correlated, p_max_factor=1.0, scale=float(np.ptp(z)),
                  constants=(("GUARD_MULTIPLE", 0.05), ("RANGE_SECONDS", 0.3)))
    feed(twins, samples, pipelined=False)
    counts = twins.python.predictor.counts
    assert counts["forecast_clamped"] > 1000
    assert counts["rls_bound"] >= 1 or not correlated  # the still axis's directions


@pytest.mark.parametrize("correlated", [True, False], ids=["correlated", "independent"])
@pytest.mark.parametrize("name", ["generalized", "one-step"])
def test_the_gate_retracts_the_same_small_outliers(name, correlated):
    """0.12-mm outliers pass the 0.15-mm gate; the forecast made from one misses the next
    sample, which agrees with the forecast made before it: both retract the outlier (as in
    tests/rhmpc/control/test_reference.py, on the sonomicrometer's stream)."""
    sim_heart = pytest.importorskip("sim.heart")
    sim_sensors = pytest.importorskip("sim.sensors")
    rng = np.random.default_rng(2)
    scenario = sim_heart.make_scenario("varying-a1-top", rng, duration=14.0)
    sensor = sim_sensors.sensor_from_name("sonomicrometry", dim=3, outliers=False,
                                          upsample=1 / DT, range_noise=0.0)
    z = sensor.measure(scenario.source, 14.0, rng).z
    twins = Twins(name, 3, gate=0.15e-3, correlated=correlated, scale=float(np.ptp(z)))
    outlier = np.array([1.2e-4, 0.0, 0.0])
    for k in range(len(z)):
        hit = k in (1300, 1400, 1500, 1639, 1691, 1743)
        twins.pipelined(k * DS, z[k] + outlier if hit else z[k], k * DT)
    twins.check_state()
    assert twins.python.predictor.counts["retracted"] >= 3


@pytest.mark.parametrize("name", ["generalized", "one-step"])
def test_arrivals_in_bursts_and_irregular_call_orders(name):
    """A slow sensor's bursts (sim.loop.closed_loop.OpenLoop._arrivals): fills and arrivals
    each updated and forecast, several updates before one interpolation, interpolations and
    forecasts with nothing new, learning at any point; stamps off the tick grid (the
    interpolation windows are cached by age, as the Python matrices)."""
    rng = np.random.default_rng(13)
    z = motion(rng, 3000, 3)
    samples = with_events(rng, z)
    twins = Twins(name, 3, gate=None, scale=float(np.ptp(z)))
    tick = 0
    for k, sample in enumerate(samples):
        tick += int(rng.integers(1, 2 * DS))
        t = tick * TS - rng.uniform(0.0, 0.03)  # jittery latency, off the grid
        for _ in range(int(rng.integers(0, 3))):  # fills of a gap in the stamps
            twins.call("update", tick, None, t)
            twins.call("predict")
        twins.call("update", tick, sample, t)
        for method in rng.permutation(["learn", "predict", "score", "none"])[:2]:
            if method != "none":
                twins.call(method)
        if k % 5 != 4:  # else the next update comes first: these points are never made
            twins.call("predict")
            twins.call("interpolate")
            twins.check(tick, int(rng.integers(1, 3 * DS)))
        if k % 7 == 0:
            twins.call("interpolate")  # nothing new: nothing changes
            twins.call("score")
    twins.check_state()
    assert twins.python.predictor.counts["outliers_rejected"] > 0


def test_a_latency_beyond_the_allocated_forecast_grows_it():
    """K = prediction_points + ⌈latency/dt⌉ beyond the points allocated at creation (K_MARGIN):
    the compiled arrays grow; the forecast-error RMS restarts with the longer K, as in Python."""
    rng = np.random.default_rng(14)
    n = 1500
    z = motion(rng, n, 3)
    twins = Twins("generalized", 3, gate=1e-3, scale=float(np.ptp(z)))
    longest = 0
    for k in range(n):
        lag = 0 if k < 500 else 90 * DS if k < 1000 else 2 * DS  # 0.68 s, then 15 ms
        twins.pipelined(k * DS, z[k], (k * DS - lag) * TS)
        longest = max(longest, twins.compiled.predictor.forecast_error_rms.shape[0])
    twins.check_state()
    assert longest > 4 + cr.K_MARGIN


@pytest.mark.parametrize("name", ["generalized", "one-step"])
def test_reset_mid_stream_starts_both_again(name):
    rng = np.random.default_rng(15)
    z = motion(rng, 1200, 3)
    samples = with_events(rng, z)
    twins = Twins(name, 3, gate=None, scale=float(np.ptp(z)))
    for k, sample in enumerate(samples):
        if k == 700:
            twins.call("reset")
            assert twins.compiled.horizon(k * DS) is None and twins.python.horizon(k * DS) is None
            assert not twins.compiled.predictor.counts and twins.compiled.gate.floor is None
            assert np.isnan(twins.compiled.mean_age)
        twins.pipelined(k * DS, None if 700 <= k < 705 else sample, k * DT)
    twins.check_state()


@pytest.mark.parametrize("guard_speed", [0.0, 0.3], ids=["guard-off", "guard-on"])
@pytest.mark.parametrize("gate", [0.0, 1e-3], ids=["gate-off", "gate-on"])
@pytest.mark.parametrize("name", ["generalized", "one-step"])
def test_a_non_finite_forecast_relearns_in_both(name, gate, guard_speed):
    """A 1e153-m sample (its square still finite): a gate rejects it; without one the predictor
    learns from it, the RLS weights overflow and either the forecast is not finite and the
    predictor relearns (``forecast_nonfinite``), or, first, the reference's guard trips."""
    rng = np.random.default_rng(16)
    z = motion(rng, 1200, 3)
    twins = Twins(name, 3, gate=gate, guard_speed=guard_speed, scale=float(np.ptp(z)))
    with np.errstate(all="ignore"):  # the Python pipeline's overflow warnings
        for k in range(len(z)):
            twins.pipelined(k * DS, np.full(3, 1e153) if k == 800 else z[k], k * DT)
    twins.check_state()
    counts = twins.python.predictor.counts
    if gate:
        assert counts["outliers_rejected"] >= 1 and not counts["forecast_nonfinite"]
    elif guard_speed and name == "generalized":  # the guard trips on the first wild points
        assert counts["reference_guard"] == 1
    else:
        assert counts["forecast_nonfinite"] == 1


@pytest.mark.parametrize("settings_dim", [None, 3])
def test_the_dimension_comes_from_the_first_sample_or_the_settings(settings_dim):
    """Missing samples before the first one: a predictor whose d is set runs its delay line
    through them, one whose d comes from the first sample cannot; both twins follow."""
    rng = np.random.default_rng(17)
    z = motion(rng, 600, 3)
    samples = [None] * 20 + with_events(rng, z)[20:]
    twins = Twins("one-step", 3, give_dim=False, settings_dim=settings_dim,
                  scale=float(np.ptp(z)))
    assert twins.compiled.predictor.d == settings_dim
    for k, sample in enumerate(samples):
        twins.pipelined(k * DS, sample, k * DT)
    twins.check_state()
    assert twins.compiled.predictor.d == 3


def test_points_before_and_after_placement():
    """Unplaced points are centred (N, d); placed mid-stream, both add the origin."""
    rng = np.random.default_rng(18)
    z = motion(rng, 800, 1)
    twins = Twins("generalized", 1, place=False, scale=float(np.ptp(z)))
    for k in range(len(z)):
        if k == 400:
            for r in twins.both:
                r.place(ORIGIN)
            twins.placed = True
            twins.check(k * DS - DS + LAG)  # the last refresh's points, placed now
        twins.pipelined(k * DS, z[k], k * DT)
    assert twins.compiled.horizon(799 * DS + LAG).shape == (N, 3)


def test_points_handed_out_are_never_changed():
    """A window kept across later refreshes keeps its values (and is read-only)."""
    rng = np.random.default_rng(19)
    z = motion(rng, 300, 3)
    twins = Twins("generalized", 3, scale=float(np.ptp(z)))
    kept = []
    for k in range(len(z)):
        twins.pipelined(k * DS, z[k], k * DT)
        if k % 50 == 10:
            block = twins.compiled.horizons(k * DS + LAG, DS)
            kept.append((block, block.copy(), block[0][None]))  # a view of a view too
    for block, copy, _ in kept:
        np.testing.assert_array_equal(block, copy)
        assert not block.flags.writeable
    assert len({id(block.base) for block, _, _ in kept}) == len(kept)


def test_samples_of_the_wrong_size_are_refused():
    pred = make_predictor("one-step", dt=DT, unit=1.0)
    compiled, _ = cr.compile_reference(PredictedReference(pred, TS, N, DS), dim=3)
    with pytest.raises(ValueError, match="components"):
        compiled.update(0, np.zeros(4), 0.0)
    compiled.update(0, [1e-3, 2e-3, 3e-3], 0.0)  # a list: the checked path
    with pytest.raises(ValueError, match="d=3"):
        compiled.update(DS, np.zeros(2), DT)
    compiled.update(DS, np.zeros((1, 3)), DT)  # reshaped, as the Python predictor does
    assert compiled.predictor.counts == {"updates": 2}


def test_what_has_no_compiled_twin_says_why(monkeypatch):
    def reference(name="one-step", **settings):
        return PredictedReference(make_predictor(name, dt=DT, **settings), TS, N, DS)

    class Tuned(OneStepRLS):
        pass

    cases = {
        "Hold": reference("hold"),
        "OneStepRLS": PredictedReference(Tuned(DT, Tuned.Settings(unit=1.0)), TS, N, DS),
        "unit": reference("generalized"),  # unit None: inferred from the data
        "dim": reference(unit=1.0, dim=2),
    }
    for expected, ref in cases.items():
        compiled, why = cr.compile_reference(ref, dim=3)
        assert compiled is None and expected in why, why
    fed = reference(unit=1.0)
    fed.refresh(0, np.zeros(3), 0.0)
    assert "fed" in cr.compile_reference(fed)[1]
    monkeypatch.setattr(cr, "_tried", True)
    monkeypatch.setattr(cr, "_library", None)
    monkeypatch.setattr(cr, "unavailable_reason", "no C compiler (cc/gcc) on PATH")
    compiled, why = cr.compile_reference(reference(unit=1.0), dim=3)
    assert compiled is None and "compiler" in why


def test_a_time_stamp_that_is_not_finite_is_refused():
    """A NaN or inf stamp is a one-line error before anything changes (the Python pipeline
    would fail later, in its interpolation)."""
    pred = make_predictor("generalized", dt=DT, unit=1.0)
    compiled, _ = cr.compile_reference(PredictedReference(pred, TS, N, DS), dim=3)
    compiled.place(ORIGIN)
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match="time stamp must be finite"):
            compiled.update(0, np.full(3, 1e-3), bad)
    assert compiled.predictor.counts == {}
    compiled.refresh(0, np.full(3, 1e-3), 0.0)
    assert compiled.horizon(0) is not None


def test_a_failed_forecast_says_why_and_reset_recovers():
    """A latency that asks for a million points fails the forecast with a one-line error until
    reset(); after it the twin works again, as the Python pipeline does."""
    pred = make_predictor("one-step", dt=DT, unit=1.0)
    compiled, _ = cr.compile_reference(PredictedReference(pred, TS, N, DS), dim=3)
    compiled.place(ORIGIN)
    compiled.update(10**9, np.full(3, 1e-3), 0.0)  # measured 500 000 s before its tick
    compiled.predict()
    with pytest.raises(MemoryError, match="million points"):
        compiled.interpolate()
    assert compiled.failure is not None
    compiled.reset()
    assert compiled.failure is None
    compiled.refresh(0, np.full(3, 1e-3), 0.0)
    np.testing.assert_allclose(compiled.horizon(0), np.tile(ORIGIN + 1e-3, (N, 1)))


def test_the_compiled_slices_refuse_a_malformed_plan_and_report_a_failed_one():
    """CompiledSlices.load checks the plan it hands to C (rows in order inside the chunk, known
    parts, one entry per slice); a slice that fails in C is reported by finish()."""
    pred = make_predictor("generalized", dt=DT, unit=1.0)
    compiled, _ = cr.compile_reference(PredictedReference(pred, TS, N, DS), dim=3)
    compiled.place(ORIGIN)
    slices = compiled.slices(np.tile(ORIGIN, (N, 1)))
    m = 30

    def plan(rows, parts, stamps=None):
        count = len(rows)
        return {"row": rows, "part": parts, "tick": np.arange(count),
                "z": np.full((count, 3), 1e-3),
                "stamp": np.zeros(count) if stamps is None else stamps,
                "fresh": np.ones(count, dtype=np.uint8)}

    charged = np.zeros((5, m), dtype=np.int64)
    for bad in (plan([0, 1], [0, 9]), plan([3, 1], [0, 1]), plan([0, m], [0, 1]),
                {**plan([0, 1], [0, 1]), "tick": np.arange(1)}):
        with pytest.raises(ValueError, match="a plan's slices"):
            slices.load(0, m, bad, charged)
    with pytest.raises(ValueError, match="charged"):
        slices.load(0, m, plan([0], [0]), np.zeros((5, m - 1), dtype=np.int64))
    slices.load(0, m, plan([0, 1, 2, 3], [0, 1, 2, 3], np.array([np.nan, 0, 0, 0])), charged)
    function = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int)(slices.function)
    for k in range(4):
        assert function(slices.state, k)  # a tick's points: never NULL
    assert (charged[:4, :4].diagonal() > 0).all()  # each slice timed on its own row
    with pytest.raises(ValueError, match="time stamp must be finite"):
        slices.finish()
