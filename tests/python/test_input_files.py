"""Files stay where they belong (issue 29 item 1; src/input.rs, FORMAT.md "Files a scene reads"):
a canary file and a canary environment variable are planted, hostile scenes point `[model] file`
at them (absolute path, `..`, a symlink out of the folder, `package://../..`, a package escape,
/proc/self/environ), and every door refuses each with a located error naming the path rule while
neither canary appears in stdout, stderr or any file it writes: `progmo validate`, `solve`,
`check --json` (its five report files), `debug`, `progmo.load` and a sweep whose `scene` escapes.
The negative control: the same scenes with $PROGMO_ALLOW_ROOTS covering the canary's folder get
past the path rule (and the file is then refused as not XML / not text, still unquoted)."""

import os
import pathlib
import subprocess
import sys

import pytest

import progmo

CANARY_FILE = "c4n4ry-file-5d0e8b71a2"
CANARY_ENV = "c4n4ry-env-93b2f6e04d"
HOSTILE = ["absolute", "dotdot", "symlink", "package_up", "package_escape", "environ"]


@pytest.fixture
def world(tmp_path):
    """tmp/secret/canary.txt (outside), tmp/share/pkg (a robot path package), tmp/scenes/*.toml."""
    secret, share, scenes = tmp_path / "secret", tmp_path / "share", tmp_path / "scenes"
    for d in (secret, share / "pkg", scenes):
        d.mkdir(parents=True)
    canary = secret / "canary.txt"
    canary.write_text(CANARY_FILE)  # one line, no newline: what an error used to echo whole
    (scenes / "link.urdf").symlink_to(canary)
    files = {
        "absolute": str(canary),
        "dotdot": "../secret/canary.txt",
        "symlink": "link.urdf",
        "package_up": "package://../secret/canary.txt",
        "package_escape": "package://pkg/../../secret/canary.txt",
        "environ": "/proc/self/environ",
    }
    for name, f in files.items():
        (scenes / f"{name}.toml").write_text(
            f'name = "{name}"\n[model]\nkind = "urdf"\nfile = "{f}"\n[initial]\n[time]\nt1 = 1.0\n')
    env = dict(os.environ, PROGMO_CANARY=CANARY_ENV, PROGMO_ROBOT_PATH=str(share))
    env.pop("PROGMO_ALLOW_ROOTS", None)
    env.pop("ROS_PACKAGE_PATH", None)
    return tmp_path, scenes, env


def run(args, env, cwd):
    r = subprocess.run([sys.executable, "-m", "progmo.command", *map(str, args)], cwd=cwd, env=env,
                       capture_output=True, text=True, timeout=600)
    return r.returncode, r.stdout + r.stderr


def assert_no_canary(text, where):
    assert CANARY_FILE not in text and CANARY_ENV not in text, f"canary in {where}:\n{text}"


def assert_no_canary_under(folder):
    files = [p for p in pathlib.Path(folder).rglob("*") if p.is_file()]
    for p in files:
        assert_no_canary(p.read_bytes().decode("utf-8", "replace"), p)
    return files


def refused_by_rule(text, name):
    """Located at the scene's `file =` line (4, column 8) and naming the path rule."""
    return (f"{name}.toml:4:8: error: model.file:" in text
            and any(p in text for p in ("outside the folder", "leaves the folder of package",
                                        "not `.` or `..`")))


@pytest.mark.parametrize("name", HOSTILE)
def test_validate_and_solve_refuse_by_the_path_rule(world, name):
    tmp, scenes, env = world
    for cmd in (["validate", scenes / f"{name}.toml"],
                ["solve", scenes / f"{name}.toml", "--out", tmp / "solve-out"]):
        code, text = run(cmd, env, tmp)
        assert code == 2 and refused_by_rule(text, name), f"{cmd[0]}: {text}"
        assert_no_canary(text, cmd[0])
    assert_no_canary_under(tmp / "solve-out") if (tmp / "solve-out").exists() else None


def test_load_refuses_in_process(world, monkeypatch):
    _, scenes, env = world
    monkeypatch.setenv("PROGMO_CANARY", CANARY_ENV)
    monkeypatch.setenv("PROGMO_ROBOT_PATH", env["PROGMO_ROBOT_PATH"])
    monkeypatch.delenv("PROGMO_ALLOW_ROOTS", raising=False)
    for name in HOSTILE:
        with pytest.raises(progmo.SceneError) as e:
            progmo.load(scenes / f"{name}.toml")
        assert refused_by_rule(str(e.value), name), str(e.value)
        assert_no_canary(str(e.value), f"progmo.load({name})")


def test_check_json_and_its_reports_hold_no_canary(world):
    tmp, scenes, env = world
    out = tmp / "check-out"
    code, text = run(["check", "--json", "--no-plots", "-s", "mujoco", "-o", out,
                      *[scenes / f"{n}.toml" for n in HOSTILE]], env, tmp)
    assert code == 2, text
    for name in HOSTILE:
        assert refused_by_rule(text, name), f"{name}: {text}"
    assert_no_canary(text, "progmo check --json")
    written = {p.name for p in assert_no_canary_under(out)}
    assert {"report.html", "results.json", "run.json", "summary.csv", "summary.md"} <= written, written


def test_check_of_a_folder_skips_a_scene_symlinked_out_of_it(world):
    tmp, scenes, env = world
    folder = tmp / "folder"
    folder.mkdir()
    (folder / "evil.toml").symlink_to(tmp / "secret" / "canary.txt")
    (folder / "environ.toml").symlink_to("/proc/self/environ")
    out = tmp / "check-folder"
    code, text = run(["check", "--json", "--no-plots", "-s", "mujoco", "-o", out, folder], env, tmp)
    assert code == 2 and "evil.toml" in text and "outside the folder" in text, text
    assert_no_canary(text, "progmo check FOLDER")
    assert_no_canary_under(out)


@pytest.mark.parametrize("name", ["dotdot", "environ"])
def test_debug_refuses(world, name):
    tmp, scenes, env = world
    code, text = run(["debug", scenes / f"{name}.toml", "--out", tmp / "debug-out"], env, tmp)
    assert code != 0 and refused_by_rule(text, name), text
    assert_no_canary(text, "progmo debug")
    if (tmp / "debug-out").exists():
        assert_no_canary_under(tmp / "debug-out")


@pytest.mark.parametrize("scene", ["../secret/canary.txt", "/proc/self/environ", "link.toml"])
def test_a_sweep_scene_stays_in_the_sweep_files_folder(world, scene):
    tmp, scenes, env = world
    (scenes / "link.toml").symlink_to(tmp / "secret" / "canary.txt")
    spec = scenes / "sweep.toml"
    spec.write_text(f'scene = "{scene}"\nsamples = 1\n[vary]\n"parameters.a" = {{ uniform = [0, 1] }}\n')
    out = tmp / "sweep-out"
    code, text = run(["sweep", "--spec", spec, "-o", out], env, tmp)
    assert code == 2 and "sweep.toml:1: scene:" in text and "outside the folder" in text, text
    assert_no_canary(text, "progmo sweep")
    if out.exists():
        assert_no_canary_under(out)


def test_negative_control_an_allowed_root_passes_the_path_rule(world):
    """With the canary's folder (and /proc) allowed, the path rule lets the files through: the
    refusals above are the rule's doing. The files are then refused for what they are, unquoted."""
    tmp, scenes, env = world
    env = dict(env, PROGMO_ALLOW_ROOTS=os.pathsep.join([str(tmp / "secret"), "/proc"]))
    for name in ("absolute", "dotdot", "symlink", "environ"):
        code, text = run(["validate", scenes / f"{name}.toml"], env, tmp)
        assert code == 2 and not refused_by_rule(text, name), f"{name}: {text}"
        assert ("not an XML document" in text or "is not text" in text), f"{name}: {text}"
        assert_no_canary(text, f"validate {name} (allowed)")
