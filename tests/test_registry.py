"""The registry derived from the model classes: every registered class (models,
extensions, covariate extensions, discovered terms, the controller's live model) is
read back from a PARAMS.json and simulated from one by the command line, and the
parameter facts each class declares agree with what the fit and the command line
read."""

import contextlib
import io
import json

import equinox as eqx
import jax
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import COVARIATE_EXTENSIONS, EXTENSIONS, AbstractExtension
from jaxcable.cli import main
from jaxcable.internal import (
    BY_CLI_NAME,
    CLASSES_BY_NAME,
    DEFAULT_CLI_MODEL,
    PARK_IDENTIFIABLE,
    cli_name,
    field_facts,
    fit_parameters,
    identifiable,
    model_document,
    parameter_info,
    parameter_table,
)


# A few dozen samples of one load-unload history on a 7 m cable (inside the range of
# Piao's surface, which the live five-element model reads).
_TIME = np.linspace(0.0, 300.0, 24)
_FORCE = np.concatenate([np.linspace(0.0, 80.0, 12), np.linspace(76.0, 10.0, 12)])
_TRANSFORMS = ("log", "log1", "linear")


def _instance(cls):
    """An instance of a registered class: a model from its defaults, an extension
    around a cheap base (Park's model where it needs one) from its fit's start."""
    if not issubclass(cls, AbstractExtension):
        return cls()
    if cls is jc.DiscoveredTerm:
        base = jc.HookeModel()
        return cls(base, theta0=2e-12, theta1=-1e-9, terms=("sigma", "sigma_rate"))
    base = jc.IntegratedModel() if cls is jc.Hereditary else jc.HookeModel()
    return cls.wrap(base)


NAMES = sorted(CLASSES_BY_NAME)
NESTED = jc.SensorDrift(jc.BeddingIn(jc.IntegratedModel(E1c=2.6e9), s_b=2e-4), 1e-9)


def _params_text(model) -> str:
    """A PARAMS.json of `model` (no fitted parameter), as `FitResult.to_json`
    writes it after reading a minimal document."""
    document = {
        "format": "jaxcable-params",
        **model_document(model),
        "fitted": [],
        "correlation": [],
        "covariance": [],
        "tests": [{"id": "t", "samples": 24, "rmse_mm": 0.0, "rmse_percent": 0.0}],
        "loss_m2": 0.0,
        "converged": True,
        "num_steps": 0,
    }
    return jc.FitResult.from_json(json.dumps(document)).to_json()


def _assert_same_model(a, b):
    assert type(a) is type(b)
    leaves_a, tree_a = jax.tree_util.tree_flatten(a)
    leaves_b, tree_b = jax.tree_util.tree_flatten(b)
    assert tree_a == tree_b
    for x, y in zip(leaves_a, leaves_b):
        assert np.shape(x) == np.shape(y) and np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_every_class_is_registered():
    expected = {
        *(e.cls for e in BY_CLI_NAME.values()),
        *EXTENSIONS.values(),
        *COVARIATE_EXTENSIONS.values(),
        jc.DiscoveredTerm,
        jc.TemperatureShiftWLF,
        jc.LiveFiveElement,
    }
    assert expected <= set(CLASSES_BY_NAME.values())
    for name, cls in CLASSES_BY_NAME.items():
        assert cls.__name__ == name and getattr(jc, name) is cls
    cli_names = [cls.CLI_NAME for cls in CLASSES_BY_NAME.values()]
    assert len(set(cli_names)) == len(cli_names)
    # The command line's --model choices stay the base models.
    assert list(BY_CLI_NAME) == [
        "integrated",
        "five-element",
        "hooke",
        "burgers",
        "bouc-wen",
        "findley",
    ]
    assert DEFAULT_CLI_MODEL == "integrated"


@pytest.mark.parametrize("name", NAMES)
def test_round_trip_through_params_json(name):
    model = _instance(CLASSES_BY_NAME[name])
    assert cli_name(model) == type(model).CLI_NAME
    text = _params_text(model)
    _assert_same_model(jc.FitResult.from_json(text).model, model)


def test_nested_round_trip_through_params_json():
    _assert_same_model(jc.FitResult.from_json(_params_text(NESTED)).model, NESTED)


def test_live_surface_round_trips():
    surface = jc.ParameterSurface(np.asarray(jc.PIAO_TABLE3.coefficients) * 1.01)
    model = jc.LiveFiveElement(surface=surface, gravity=9.81)
    _assert_same_model(jc.FitResult.from_json(_params_text(model)).model, model)


@pytest.fixture(scope="module")
def history(tmp_path_factory):
    path = tmp_path_factory.mktemp("registry") / "history.csv"
    data = jc.TestData(
        time=_TIME,
        force=_FORCE,
        metadata={"id": "registry", "length_mm": 7000.0, "control": "force"},
    )
    jc.write_csv(path, data)
    return path


def _simulate(history, model, tmp_path, *extra):
    params = tmp_path / "PARAMS.json"
    params.write_text(_params_text(model))
    out = tmp_path / "out.csv"
    stdout, stderr = io.StringIO(), io.StringIO()
    argv = ["simulate", history, "--params", params, "--out", out, *extra]
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = main([str(a) for a in argv])
    return status, stdout.getvalue() + stderr.getvalue(), out


@pytest.mark.parametrize("name", NAMES)
def test_simulate_from_params_json(history, tmp_path, name):
    model = _instance(CLASSES_BY_NAME[name])
    status, output, out = _simulate(history, model, tmp_path)
    assert status == 0, output
    data = jc.read_csv(out)
    assert np.all(np.isfinite(data.elongation))
    assert data.metadata["model"].startswith(type(model).CLI_NAME)


def test_simulate_nested_with_its_base_named(history, tmp_path):
    status, output, out = _simulate(history, NESTED, tmp_path, "--model", "integrated")
    assert status == 0, output
    assert jc.read_csv(out).metadata["model"] == (
        "sensor-drift(bedding-in(integrated))"
    )
    status, output, _ = _simulate(history, NESTED, tmp_path, "--model", "hooke")
    assert status != 0 and "--model integrated" in output


@pytest.mark.parametrize("name", NAMES)
def test_parameter_facts_agree(name):
    cls = CLASSES_BY_NAME[name]
    facts = field_facts(cls)
    assert facts, name
    for field, f in facts.items():
        info = parameter_info(cls, field)
        assert (info is None) == (f.transform is None)
        if info is not None:
            assert info.unit, (name, field)
            assert info.transform in _TRANSFORMS or info.transform.startswith("tanh:")
    table = parameter_table(cls)
    assert all(f"`{field}`" in table for field in facts)
    if issubclass(cls, AbstractExtension):
        assert cls.EFFECT_FIELDS == fit_parameters(cls)
        assert cls.SIZE_FIELD in cls.EFFECT_FIELDS
        assert cls.SIZE_UNIT == facts[cls.SIZE_FIELD].unit
        assert cls.EXTENSION_ID == cls.CLI_NAME.replace("-", "_")


def test_identifiable_from_the_declarations():
    expected = ("E1c", "E1r", "E2r", "t_r1", "E3r", "t_e")
    assert identifiable(jc.IntegratedModel()) == expected == PARK_IDENTIFIABLE
    assert BY_CLI_NAME["integrated"].identifiable == expected
    for cls in (jc.HookeModel, jc.BurgersModel, jc.FiveElementModel, jc.BeddingIn):
        assert identifiable(_instance(cls)) is None


def test_declared_checks():
    with pytest.raises(ValueError, match=r"`IntegratedModel.t_e` must be positive"):
        jc.IntegratedModel(t_e=-1.0)
    with pytest.raises(ValueError, match=r"BeddingIn `s_b` must be non-negative"):
        jc.BeddingIn(jc.HookeModel(), s_b=-1.0)
    with pytest.raises(ValueError, match=r"SecondRetardation `E_k`.*inf switches"):
        jc.SecondRetardation(jc.HookeModel(), E_k=np.nan)
    model = jc.BeddingIn(jc.HookeModel(), s_b=1e-4)
    cable = jc.Cable(0.3)
    assert model.check(cable) == jc.RESULTS.successful
    bad = eqx.tree_at(lambda m: m.F_b, model, np.asarray(-1.0))
    assert bad.check(cable) == jc.RESULTS.parameter_out_of_domain


def test_candidate_facts():
    assert jc.CovariateStrain.LIBRARY_TERM == "c_rate"
    assert jc.MechanoSorptive.LIBRARY_TERM == "sigma_c_abs_rate"
    assert jc.BeddingIn.LIBRARY_TERM is None

    class Test:
        def __init__(self, temperature):
            self.temperature = temperature

    flat = [Test(np.full(3, 293.0)), Test(np.full(3, 293.5))]
    assert "no temperature contrast" in jc.TemperatureShift.applicability(flat)
    assert "not every test" in jc.TemperatureShift.applicability([Test(None)])
    assert jc.TemperatureShift.applicability([*flat, Test(np.full(3, 300.0))]) == ""
    assert jc.BeddingIn.applicability(flat) == ""


def test_fit_names_of_a_wrapped_model():
    from jaxcable.internal import cli_common, cli_models

    model = NESTED.base  # BeddingIn(IntegratedModel)
    names = cli_models.names_option(
        "s_b,base.E1c", "--fit", model, "bedding-in(integrated)"
    )
    assert names == ["s_b", "base.E1c"]
    with pytest.raises(cli_common.CliError, match="'E1c' is not a parameter"):
        cli_models.names_option("E1c", "--fit", model, "bedding-in(integrated)")
