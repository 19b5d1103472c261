"""Start-up cost of the ``streetaug`` command: what importing the CLI and printing help must not load.

Each check runs a fresh interpreter (the test process has long since imported everything) and reads its
``sys.modules``: torch, scipy and embree are the slow imports (~1 s, ~0.2 s, ~0.1 s), and the batch
machinery / pipeline / dataset reader pull them in. The default ``insert`` on a bundled scene runs without
torch at all.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("torch", "scipy", "embreex")
PROJECT_HEAVY = ("streetaug.augment.batch", "streetaug.augment.pipeline", "streetaug.augment.lighting",
                 "streetaug.placement", "streetaug.datasets")
COMMANDS = ("batch", "bench", "class-sizes", "insert", "make-samples", "merge", "predict-light", "stability",
            "train-light", "train-sky")


def loaded_after(code: str) -> dict:
    """Run ``code`` in a fresh interpreter; return {"modules": [...] loaded, "stdout": ...}."""
    probe = (
        "import contextlib, io, json, sys\n"
        "out = io.StringIO()\n"
        "with contextlib.redirect_stdout(out):\n"
        + "".join(f"    {line}\n" for line in code.splitlines())
        + "print(json.dumps({'modules': sorted(sys.modules), 'stdout': out.getvalue()}))\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def run_cli(args: list[str]) -> str:
    """Code that runs ``streetaug ARGS`` in-process, swallowing click's exit."""
    return f"import streetaug.cli.main as m\ntry:\n    m.main({args!r})\nexcept SystemExit:\n    pass"


def heavy_in(modules: list[str], names: tuple[str, ...]) -> list[str]:
    """The modules that are one of ``names`` or inside one of them."""
    return sorted(m for m in modules if any(m == n or m.startswith(n + ".") for n in names))


def test_importing_the_cli_loads_no_torch_scipy_or_embree():
    modules = loaded_after("import streetaug.cli.main")["modules"]
    assert "streetaug.cli.main" in modules
    assert heavy_in(modules, HEAVY) == []
    assert heavy_in(modules, PROJECT_HEAVY) == []


def test_help_lists_every_command_without_heavy_imports():
    result = loaded_after(run_cli(["--help"]))
    rows = result["stdout"].split("Commands:")[1].splitlines()
    listed = [row.split()[0] for row in rows if row.startswith("  ") and not row.startswith("   ")]
    assert listed == list(COMMANDS)  # all of them, sorted as click sorts
    assert heavy_in(result["modules"], HEAVY) == []
    assert heavy_in(result["modules"], PROJECT_HEAVY) == []


@pytest.mark.parametrize("command", COMMANDS)
def test_command_help_loads_no_heavy_modules(command):
    result = loaded_after(run_cli([command, "--help"]))
    assert "Usage: " in result["stdout"] and command in result["stdout"]
    assert heavy_in(result["modules"], HEAVY) == []


@pytest.mark.parametrize("scene", ["sample-sunny", "sample-lowsun", "sample-overcast"])
def test_the_default_insert_on_a_bundled_scene_never_imports_torch(scene, tmp_path):
    """The volume levels (L2/L3) query the light volume with numpy; torch is for training and the sky network
    (L1 without metadata), which the bundled scenes (location and timestamp known) never run."""
    out = tmp_path / scene
    result = loaded_after(run_cli(["insert", "--scene", scene, "--out", str(out)]))
    labels = json.loads((out / "labels.json").read_text())
    assert labels["objects"] and (out / "image.jpg").is_file()
    assert heavy_in(result["modules"], ("torch",)) == [], labels["lighting"]["level"]
    assert "streetaug.augment.lighting.skynet.predict" not in result["modules"]
    if scene == "sample-sunny":  # the volume really ran
        assert labels["lighting"]["level"] in ("L2", "L3") and "streetaug.augment.lighting.volume" in result["modules"]


def test_a_command_imports_only_its_own_module():
    modules = loaded_after(run_cli(["train-sky", "--help"]))["modules"]
    assert "streetaug.cli.train" in modules
    assert not {"streetaug.cli.batch", "streetaug.cli.bench", "streetaug.cli.stability"} & set(modules)


def test_library_imports_pause_the_gc_and_freeze_once():
    code = (
        "import gc\n"
        "from streetaug.cli.common import library_imports\n"
        "before = gc.get_freeze_count()\n"
        "with library_imports():\n"
        "    paused = not gc.isenabled()\n"
        "    import email.mime.text\n"
        "frozen = gc.get_freeze_count()\n"
        "with library_imports():\n"
        "    import xml.dom.minidom\n"
        "print(paused, gc.isenabled(), before == 0 < frozen, gc.get_freeze_count() == frozen)"
    )
    assert loaded_after(code)["stdout"].split() == ["True", "True", "True", "True"]
