"""A strain beyond the cable's breaking strain (`Cable.breaking_strain`) is reported as
`RESULTS.strain_beyond_break` by every drive, the controller and the Monte-Carlo, and
changes no number of a simulation up to the sample that breaks (none of one that stays
below it)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import cdpr


# Parameters pinned here (not the library defaults, which calibration may change). At
# 1900 N (95 % of the 2000 N breaking load) the spring alone strains a 3 mm cable by
# 0.12, and the dashpot creeps it by 1.7e-3 / s.
MODEL = jc.BurgersModel(E1=2.2e9, eta0=1.6e11, E2=3.7e8, eta2=3.7e10)
LENGTH = 0.3
# Far below the strain of any load that the cable feels: crossed by every history
# here whatever the parameters (a polymer's modulus is far below 1900 N / (A 1e-4)).
TINY = 1e-4
# A day at 95 % of the breaking load: strains up to ~150, beyond any breaking strain.
TIME = np.linspace(0.0, 24 * 3600.0, 11)
HELD = np.full(11, 0.95 * 2000.0)
MATCH = "breaking strain"


def _cable(breaking_strain, **kwargs):
    return jc.Cable(length=LENGTH, breaking_strain=breaking_strain, **kwargs)


def _held(breaking_strain, throw=False):
    return jc.simulate_force_history(
        MODEL, _cable(breaking_strain), TIME, HELD, method=jc.Simulation(throw=throw)
    )


@pytest.fixture(scope="module")
def unbroken():
    # math.inf: the reference, never flagged.
    return _held(math.inf)


def test_infinite_breaking_strain_never_flags(unbroken):
    assert unbroken.result == jc.RESULTS.successful
    assert float(np.max(unbroken.strain)) > 100.0


def test_force_history_beyond_break(unbroken):
    traj = _held(TINY)
    assert traj.result == jc.RESULTS.strain_beyond_break
    with pytest.raises(Exception, match=MATCH):
        _held(TINY, throw=True)
    # The default breaking strain is crossed too (the held strain reaches ~150).
    default = jc.simulate_force_history(
        MODEL, jc.Cable(length=LENGTH), TIME, HELD, method=jc.Simulation(throw=False)
    )
    assert default.result == jc.RESULTS.strain_beyond_break
    # The check reads the result only: every number is the unbroken simulation's.
    for name in ("time", "force", "strain", "elongation", "mask"):
        np.testing.assert_array_equal(getattr(traj, name), getattr(unbroken, name))


def test_below_the_breaking_strain_is_successful(unbroken):
    peak = float(np.max(unbroken.strain))
    assert _held(1.01 * peak).result == jc.RESULTS.successful
    assert _held(0.99 * peak).result == jc.RESULTS.strain_beyond_break


def test_one_result_per_cable_under_vmap(unbroken):
    cables = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, (4,)),
        _cable(jnp.array([TINY, math.inf, 2.0, 1e3])),
    )
    traj = jax.vmap(
        lambda c: jc.simulate_force_history(
            MODEL, c, TIME, HELD, method=jc.Simulation(throw=False)
        )
    )(cables)
    # 2.0 is passed at the first sample beyond it, 1e3 never.
    strain = np.asarray(unbroken.strain)
    assert strain.min() < 2.0 < strain.max() < 1e3
    broken = np.asarray(traj.result == jc.RESULTS.strain_beyond_break)
    successful = np.asarray(traj.result == jc.RESULTS.successful)
    np.testing.assert_array_equal(broken, [True, False, True, False])
    np.testing.assert_array_equal(successful, ~broken)
    np.testing.assert_array_equal(traj.strain, np.broadcast_to(strain, (4, 11)))


def test_first_failure_is_kept():
    # Traced forces (inside jit) skip the boundary's checks, so a negative force is
    # flagged in the kernel: whichever of it and the break comes first is reported.
    @jax.jit
    def result(force):
        traj = jc.simulate_force_history(
            MODEL, _cable(TINY), TIME, force, method=jc.Simulation(throw=False)
        )
        return traj.result

    negative_first = np.where(np.arange(11) == 1, -1.0, np.where(TIME > 3e4, 10.0, 0.0))
    broken_first = np.where(np.arange(11) == 8, -1.0, HELD)
    assert result(negative_first) == jc.RESULTS.nonphysical_force
    assert result(broken_first) == jc.RESULTS.strain_beyond_break


@pytest.mark.parametrize("drive", ["rate", "elongation"])
def test_solved_drives_beyond_break(drive):
    # 50 mm/min on 300 mm (2.8e-3 / s) outruns the dashpot's creep at 100 N
    # (8.8e-5 / s): every force of the protocol is reached.
    speed = 50e-3 / 60

    def run(breaking_strain, throw=False):
        cable = _cable(breaking_strain, speed=speed)
        if drive == "rate":
            protocol = jc.Protocol.cycles(100.0, 1, 5)
            return jc.simulate_rate_test(
                MODEL, cable, protocol, method=jc.Simulation(throw=throw)
            )
        # An imposed strain up to 2e-3: beyond TINY whatever the model.
        time = np.linspace(0.0, 60.0, 7)
        elongation = np.linspace(0.0, 2e-3 * LENGTH, 7)
        return jc.simulate_elongation_history(
            MODEL, cable, time, elongation, method=jc.Simulation(throw=throw)
        )

    unbroken = run(math.inf)
    assert unbroken.result == jc.RESULTS.successful
    peak = float(np.max(unbroken.strain))
    assert peak > 10 * TINY
    # A breaking strain never reached: successful, and every number the same.
    below = run(1.01 * peak)
    assert below.result == jc.RESULTS.successful
    for name in ("time", "force", "strain"):
        np.testing.assert_array_equal(getattr(below, name), getattr(unbroken, name))
    traj = run(TINY)
    assert traj.result == jc.RESULTS.strain_beyond_break
    # The same up to the sample that breaks; after it, as after any failure, the
    # samples are no longer solved.
    k = int(np.flatnonzero(np.asarray(unbroken.strain) > TINY)[0]) + 1
    for name in ("time", "force", "strain"):
        np.testing.assert_array_equal(
            getattr(traj, name)[:k], getattr(unbroken, name)[:k]
        )
    with pytest.raises(Exception, match=MATCH):
        run(TINY, throw=True)


def test_controller_step_beyond_break():
    cables = jc.Cable(
        length=jnp.array([LENGTH, LENGTH]),
        breaking_strain=jnp.array([TINY, math.inf]),
    )
    state = jc.controller_init(MODEL, cables)
    forces = jnp.full(2, HELD[0])
    new, elongation = jc.controller_step(MODEL, cables, state, 1.0, forces, throw=False)
    np.testing.assert_array_equal(
        new.result == jc.RESULTS.strain_beyond_break, [True, False]
    )
    np.testing.assert_array_equal(new.result == jc.RESULTS.successful, [False, True])
    # Both cables are the same but for the breaking strain: the same elongation.
    assert elongation[0] == elongation[1]
    with pytest.raises(Exception, match=MATCH):
        jax.block_until_ready(jc.controller_step(MODEL, cables, state, 1.0, forces))


def test_monte_carlo_counts_the_broken_draws():
    # Two cables that differ only in their breaking strain, one force history
    # shared; the drawn dashpot spreads the creep of the draws.
    num_draws = 8
    sampler = jc.IndependentParameters(MODEL, {"eta0": jc.LogNormal(1.6e11, 0.5)})
    time = np.linspace(0.0, 3600.0, 6)
    loads = jc.ForceHistory(time, np.full(6, 100.0))

    def run(breaking_strain):
        cables = jc.Cable(
            length=jnp.array([LENGTH, LENGTH]),
            breaking_strain=jnp.asarray(breaking_strain),
        )
        return jc.monte_carlo(
            sampler,
            cables,
            loads,
            progress_meter=jc.NoProgressMeter(),
            method=jc.MonteCarlo(
                key=jax.random.key(0),
                num_draws=num_draws,
                method="exact",
                keep_draws=True,
            ),
        )

    free = run([math.inf, math.inf])
    np.testing.assert_array_equal(free.num_broken, [0, 0])
    np.testing.assert_array_equal(free.num_successful, [num_draws, num_draws])
    # The first cable's breaking strain halfway between the 4th and 5th largest peak
    # strains of the draws: exactly half of them pass it.
    peak = np.max(np.asarray(free.elongation)[:, 0], axis=-1) / LENGTH
    low, high = np.sort(peak)[num_draws // 2 - 1 : num_draws // 2 + 1]
    assert low < high
    res = run([(low + high) / 2, math.inf])
    np.testing.assert_array_equal(res.num_broken, [num_draws // 2, 0])
    np.testing.assert_array_equal(
        res.status_counts["strain_beyond_break"], res.num_broken
    )
    np.testing.assert_array_equal(res.num_successful, [num_draws // 2, num_draws])
    # The broken draws are those whose peak passed it; the others keep their numbers.
    broken = np.isnan(np.asarray(res.elongation)[:, 0, -1])
    np.testing.assert_array_equal(broken, peak > (low + high) / 2)
    np.testing.assert_array_equal(
        np.asarray(res.elongation)[~broken], np.asarray(free.elongation)[~broken]
    )


@pytest.mark.parametrize("value", [0.0, -0.01, -math.inf, math.nan])
def test_breaking_strain_must_be_positive(value):
    with pytest.raises(ValueError, match="`breaking_strain`"):
        jc.Cable(length=LENGTH, breaking_strain=value)
    with pytest.raises(ValueError, match="`breaking_strain`"):
        jc.Cable.from_mm(length_mm=300.0, breaking_strain=value)


def test_breaking_strain_fields():
    assert float(jc.Cable(length=LENGTH).breaking_strain) == jc.DEFAULT_BREAKING_STRAIN
    assert float(jc.Cable(length=LENGTH, breaking_strain=math.inf).breaking_strain) == (
        math.inf
    )
    cable = jc.Cable.from_mm(length_mm=300.0, breaking_strain=0.04)
    assert float(cable.breaking_strain) == 0.04
    robot = cdpr.Robot()
    assert float(robot.cables(jnp.ones(8)).breaking_strain) == (
        jc.DEFAULT_BREAKING_STRAIN
    )


def test_breaking_strain_from_file_metadata(tmp_path):
    path = tmp_path / "test.csv"
    rows = "time_s,force_N\n0,0\n1,1\n"
    path.write_text(f"# length_mm: 300\n# breaking_strain: 0.04\n{rows}")
    data = jc.read_csv(path)
    assert data.metadata["breaking_strain"] == 0.04
    assert float(data.cable().breaking_strain) == 0.04
    # A material that does not break: read, and written back, as inf.
    path.write_text(f"# length_mm: 300\n# breaking_strain: inf\n{rows}")
    data = jc.read_csv(path)
    assert float(data.cable().breaking_strain) == math.inf
    jc.write_csv(tmp_path / "again.csv", data)
    assert jc.read_csv(tmp_path / "again.csv").metadata["breaking_strain"] == math.inf
    path.write_text(f"# length_mm: 300\n# breaking_strain: 0\n{rows}")
    with pytest.raises(ValueError, match="breaking_strain.*must be positive"):
        jc.read_csv(path)
