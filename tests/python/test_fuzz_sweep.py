"""Bounded, deterministic version of the sweep-file fuzz target (fuzz/python/sweep_target.py,
atheris): a fixed-seed mutation loop over the bundled sweep files (and a few variants that reach
grids, solver settings and scene paths) through the same body (fuzz/python/sweep_body.py): only the
documented errors, every input done within a time bound. A few seconds; the long coverage-guided
run is the atheris target. The inputs the fuzzer found are regression cases here."""

import random
import shutil
import re
import sys
import time
from pathlib import Path

import pytest

from progmo import data
from progmo import sweep as sw

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "fuzz" / "python"))
import sweep_body  # noqa: E402

#: seconds any one input may take (the atheris run uses -timeout=10; a sweep file is read in ms)
BOUND = 2.0
CASES = 2000

VARIANTS = [
    b'scene = "double_pendulum"\nsamples = 2\nseed = 1\nsimulators = ["solver_only"]\n'
    b'initial_state = "assemble"\nhorizon = 0.5\nstep = 1e-3\n[vary]\n'
    b'"solver.rtol" = { grid = [1e-8, 1e-10] }\n"parameters.w" = { loguniform = [0.5, 2.0] }\n'
    b'"initial.v.q1" = { normal = [0.0, 0.1] }\n',
    b'scene = "sub/../double_pendulum.toml"\n[vary]\n"parameters.amp" = { grid = [0.1, 0.2, 0.3] }\n',
]

TOKENS = [b"[vary]\n", b'"parameters.amp"', b'"initial.q.q2"', b'"solver.atol"', b"{ grid = [1, 2] }",
          b"{ uniform = [-1e308, 1e308] }", b"{ normal = [0, 1e308] }", b"{ loguniform = [5e-324, 1e308] }",
          b"= ", b"[", b"]", b"{", b"}", b",", b'"', b"'", b"\n", b"#", b"nan", b"inf", b"-1", b"0",
          b"1e308", b"99999999999999999999999999", b"true", b"\xff", b"\x00", b"\xef\xbb\xbf",
          b"samples = 1000000000000\n", b'scene = "../../x"\n', b"seed = -1\n"]


def seeds() -> list[bytes]:
    bundled = sorted((data.references() / "sweeps").glob("*.toml"))
    assert bundled, "no bundled sweep files"
    return [p.read_bytes() for p in bundled] + VARIANTS


def mutate(rng: random.Random, b: bytes) -> bytes:
    out = bytearray(b)
    for _ in range(rng.randint(1, 5)):
        at = rng.randint(0, len(out))
        op = rng.randrange(5)
        if op == 0:
            del out[at:at + rng.randint(1, 30)]
        elif op == 1:
            out[at:at] = rng.choice(TOKENS)
        elif op == 2 and out:
            out[min(at, len(out) - 1)] = rng.randrange(256)
        elif op == 3:
            out[at:at] = out[at:at + rng.randint(1, 120)]
        else:
            lines = bytes(out).split(b"\n")
            rng.shuffle(lines)
            out = bytearray(b"\n".join(lines))
    return bytes(out)


def run(b: bytes, folder: Path) -> None:
    t = time.perf_counter()
    sweep_body.one_input(b, folder)
    dt = time.perf_counter() - t
    assert dt < BOUND, f"{dt:.1f} s for {b!r}"


def test_the_seeds_load_and_make_samples(tmp_path):
    for b in seeds():
        sw.load_spec(_write(tmp_path, b))  # no error: the mutations start from valid files
        run(b, tmp_path)


def test_mutated_sweep_files_raise_only_documented_errors():
    rng = random.Random(20261126)
    base = seeds()
    folder = sweep_body.folder()
    try:
        for _ in range(CASES):
            run(mutate(rng, rng.choice(base)), folder)
    finally:
        shutil.rmtree(folder)


def _write(folder: Path, b: bytes) -> Path:
    p = folder / "s.toml"
    p.write_bytes(b)
    return p


# What the fuzzer found (each raised another exception, or hung, before the fix): the input and
# the located SweepError it must now give.
BIG = "9" * 400
FOUND = [
    # not UTF-8: UnicodeDecodeError; now located at the byte, not quoted
    (b'seed = 1\n[vary]\n"parameters.amp" = { grid = [0.1, 0.2\xdd 0.3] }\n',
     r":3:38: the sweep file is not valid UTF-8 \(an invalid byte at line 3, column 38\)"),
    # an integer beyond the floats: OverflowError in math.isfinite / float()
    (f'[vary]\n"parameters.amp" = {{ grid = [1, {BIG}] }}\n'.encode(), r":2:1: vary.parameters.amp: grid needs a list of finite numbers"),
    (f'horizon = {BIG}\n[vary]\n"parameters.amp" = {{ grid = [1] }}\n'.encode(), r":1:1: horizon: must be a finite number > 0"),
    # a uniform range wider than the floats: numpy's OverflowError at the first sample
    (b'[vary]\n"parameters.amp" = { uniform = [-1e308, 1e308] }\n', r":2:1: vary.parameters.amp: uniform needs b - a finite"),
    # 10^7 grid points x 10 draws: the grid was formed as a list for every sample (a hang)
    (b'[vary]\n' + b''.join(f'"{k}" = {{ grid = [1,2,3,4,5,6,7,8,9,10] }}\n'.encode() for k in (
        "parameters.amp", "parameters.w", "initial.q.q1", "initial.q.q2", "initial.v.q1", "initial.v.q2", "solver.rtol")),
     r":2:1: vary.parameters.amp: 10 draw\(s\) x 10000000 grid point\(s\) = 1e\+08 samples, more than the 100000"),
    (b'samples = 9223372036854775807\n[vary]\n"parameters.amp" = { uniform = [0, 1] }\n', r":1:1: samples: 92233720"),
    # a scene name the file system refuses (too long): OSError from Path.exists
    (b'scene = "' + b"a" * 5000 + b'"\n[vary]\n"parameters.amp" = { uniform = [0, 1] }\n', r":1: scene: not a usable path"),
]


@pytest.mark.parametrize("text,where", FOUND, ids=["not_utf8", "int_beyond_floats", "horizon_beyond_floats",
                                                   "uniform_too_wide", "grid_too_large", "samples_too_many",
                                                   "scene_name_too_long"])
def test_what_the_fuzzer_found_is_a_located_sweep_error(tmp_path, text, where):
    p = _write(tmp_path, text)
    t = time.perf_counter()
    with pytest.raises(sw.SweepError, match=re.escape(str(p)) + where):
        spec = sw.load_spec(p)
        sw.spec_scene(spec)
    assert time.perf_counter() - t < BOUND
    run(text, tmp_path)  # and the fuzz body accepts it


def test_grid_points_are_those_of_the_formed_grid(tmp_path):
    """Spec.values no longer forms the grid: the same points, in the same order, as before."""
    spec = sw.load_spec(_write(tmp_path, b'samples = 2\n[vary]\n"solver.rtol" = { grid = [1e-8, 1e-9, 1e-10] }\n'
                                         b'"parameters.amp" = { uniform = [0, 1] }\n'
                                         b'"parameters.w" = { grid = [1, 2] }\n'))
    grid = spec.grid()
    assert len(grid) == 6 and spec.total() == 12
    for i in range(spec.total()):
        v = spec.values(i)
        assert {k: v[k] for k in grid[0]} == grid[i // spec.samples]
