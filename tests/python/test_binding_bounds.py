"""The binding refuses unbounded or meaningless work with ValueError, through the core's own checks
(progmo::solve::validate, ChainSpec::check): no hang, no abort, no NaN results for NaN inputs."""

import math
import pathlib
import time

import numpy as np
import pytest

import progmo as ph
from progmo._core import chain_toml

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENE = str(ROOT / "references" / "scenes" / "double_pendulum.toml")


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(integrator="rk4", step=math.nan), "step"),
        (dict(integrator="rk4", step=0.0), "step"),
        (dict(integrator="rk4", step=-1.0), "step"),
        (dict(integrator="rk4", step=1e-300), "step"),
        (dict(t1=math.inf), "t1"),
        (dict(t1=math.nan), "t1"),
        (dict(output_dt=1e-300), "output_dt"),
        (dict(output_dt=5e-324), "output_dt"),
        (dict(t1=1e9, output_dt=1e-3), "output_dt"),
        (dict(rtol=math.nan), "rtol"),
        (dict(max_samples=1000), "output_dt"),
    ],
)
def test_solve_refuses_before_integrating(kwargs, name):
    s = ph.Scene(SCENE)
    start = time.monotonic()
    with pytest.raises(ValueError, match=f"^{name}: "):
        s.solve(**kwargs)
    assert time.monotonic() - start < 5


def test_max_samples_boundary_passes():
    # double_pendulum samples 0.01 s over 10 s: 1001 samples.
    r = ph.Scene(SCENE).solve(max_samples=1001)
    assert r.success and len(r.t) == 1001


def test_nan_inputs_raise():
    s = ph.Scene(SCENE)
    r = s.solve(output_dt=0.5)
    q = r.q.copy()
    q[1, 0] = math.nan
    with pytest.raises(ValueError, match="q: entry 2 is NaN"):
        s.residuals(r.t, q, r.v)
    with pytest.raises(ValueError, match="v: entry 0 is inf"):
        s.dynamics(0.0, np.zeros(2), np.array([math.inf, 0.0]))
    with pytest.raises(ValueError, match="t: entry 0 is NaN"):
        s.dynamics(math.nan, np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match="q: entry 1 is NaN"):
        s.accelerations(0.0, np.array([0.0, math.nan]), np.zeros(2), "kkt")


def test_chain_toml_bounds_its_size_and_escapes_the_name(tmp_path):
    with pytest.raises(ValueError, match="2 to 10000 links"):
        chain_toml(10**9)
    with pytest.raises(ValueError, match="length must be finite"):
        chain_toml(3, length=math.nan)
    text = chain_toml(3, name='x"\n[solver]\nrtol = 1e-3\n#')
    path = tmp_path / "chain.toml"
    path.write_text(text)
    scene = ph.Scene(str(path))
    assert scene.name == 'x"\n[solver]\nrtol = 1e-3\n#'
    assert scene.settings["rtol"] == 1e-10
