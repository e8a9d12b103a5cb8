"""The package ships what its documentation runs: the configs, system files,
extreme cases and the example scene are package data (pyproject.toml's
globs), they are in a built wheel, and every ``configs/...`` and
``examples/...`` path the pages name is read from the package in a folder
that holds no copy of it; ``nsga-jax config --list`` lists them,
``nsga-jax config FILE`` prints one that runs elsewhere, and
``nsga-jax --version`` names the installed version."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from importlib.metadata import version
from pathlib import Path

import pytest

from nsga_jax._cli import main
from nsga_jax._packaged import ROOT as PACKAGE
from nsga_jax._packaged import locate, packaged, packaged_files
from nsga_jax.scenes import configure, resolve_scene

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
DOCUMENTED = sorted({path for page in PAGES for path in
                     re.findall(r"(?<![\w/.])((?:configs|examples)/[\w./-]*\w\.(?:py|toml))\b", page.read_text())})
"""Every configs/... and examples/... file the pages name, as they name it."""


def package_data() -> set[str]:
    """The files pyproject.toml's package-data globs put in the wheel, relative to nsga_jax/."""
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["nsga_jax"]
    return {p.relative_to(PACKAGE).as_posix() for g in globs for p in PACKAGE.glob(g) if p.is_file()}


def test_package_data_covers_every_config_and_example():
    shipped = package_data()
    on_disk = {p.relative_to(PACKAGE).as_posix() for folder in ("configs", "examples")
               for p in (PACKAGE / folder).rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    assert len(on_disk) > 30
    assert on_disk <= shipped, sorted(on_disk - shipped)
    assert set(packaged_files()) <= shipped
    assert "py.typed" in shipped


def test_the_pages_name_packaged_files_only_and_each_resolves_from_any_folder(tmp_path, monkeypatch):
    assert "configs/rigid_box.toml" in DOCUMENTED and "examples/double_pendulum.py" in DOCUMENTED
    monkeypatch.chdir(tmp_path)  # no configs/ or examples/ here
    for path in DOCUMENTED:
        assert packaged(path) is not None, f"{path} is named in the pages but not packaged"
        assert locate(path) == packaged(path)
        name, config = resolve_scene(path)
        assert name or config is not None
        if config is not None:
            configure(path)  # a config: its scene and every value valid


def test_a_file_in_the_current_folder_comes_before_the_packaged_one(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "configs").mkdir()
    (tmp_path / "configs" / "rigid_box.toml").write_text('scene = "bouncing_ball"\n')
    assert locate("configs/rigid_box.toml") == Path("configs/rigid_box.toml")
    assert configure("configs/rigid_box.toml").spec.name == "bouncing_ball"
    assert packaged("configs/../pyproject.toml") is None and packaged("other/rigid_box.toml") is None


def test_a_packaged_config_runs_from_another_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "ball"
    assert main(["run", "configs/bouncing_ball.toml", "--t-end", "0.05", "--out", str(out), "--quiet",
                 "--no-cache"]) == 0
    assert json.loads((out / "summary.json").read_text())["n_steps"] == 50


def test_config_list_names_every_packaged_file(capsys):
    assert main(["config", "--list"]) == 0
    out = capsys.readouterr().out
    assert str(PACKAGE) in out
    for name in packaged_files():
        assert re.search(rf"^  {re.escape(name)}\s+\S", out, re.M), name


def test_config_prints_a_packaged_config_that_runs_elsewhere(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["config", "examples/double_pendulum.toml"]) == 0
    text = capsys.readouterr().out
    scene = json.dumps(str(PACKAGE / "examples" / "double_pendulum.py"))
    assert f"scene = {scene}" in text  # the scene file beside it, by its absolute path
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "mine.toml").write_text(text)
    configured = configure(tmp_path / "elsewhere" / "mine.toml")
    assert configured.spec.name == "double_pendulum_masses" and configured.parameters["e"] == 0.5
    assert main(["config", "configs/rigid_box.toml"]) == 0
    assert capsys.readouterr().out == (PACKAGE / "configs" / "rigid_box.toml").read_text()


def test_config_without_a_scene_or_with_both_is_refused(capsys):
    assert main(["config"]) == 2
    assert "error: config expects a scene name" in capsys.readouterr().err
    assert main(["config", "--list", "bouncing_ball"]) == 2
    assert "error: config --list takes no scene, got 'bouncing_ball'" in capsys.readouterr().err


def test_version_is_the_installed_one(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out == f"nsga-jax {version('nsga_jax')}\n"


@pytest.mark.slow  # building the wheel takes 7 s or more (setuptools in an isolated environment)
def test_the_wheel_holds_the_configs_examples_and_metadata(tmp_path):
    source = tmp_path / "source"  # what the wheel is built from, and no stale build/ folder
    shutil.copytree(ROOT / "nsga_jax", source / "nsga_jax", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "-q", "-w", str(tmp_path)],
                   check=True, cwd=tmp_path, timeout=300)
    wheel, = tmp_path.glob("nsga_jax-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = sorted(f"nsga_jax/{name}" for name in package_data() if f"nsga_jax/{name}" not in names)
    assert not missing, missing
    assert not [n for n in names if n.startswith(("tests/", "docs/", "experiments/"))]
    metadata = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    for field in ("License-Expression: Apache-2.0", "License-File: LICENSE", "Classifier: Topic :: Scientific",
                  "Keywords: ", "Author: The nsga_jax developers", "Description-Content-Type: text/markdown",
                  "Requires-Python: >=3.11"):
        assert field in metadata, field
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert "# nsga_jax" in metadata  # README.md as the long description


def test_the_system_files_page_lists_every_packaged_system_file():
    page = (ROOT / "docs" / "system-files.md").read_text()
    table = set(re.findall(r"^\| `(configs/systems/[\w.]+\.toml)` \|", page, re.M))
    shipped = {name for name in packaged_files() if name.startswith("configs/systems/")}
    assert table == shipped
    assert f"{['', 'One', 'Two', 'Three', 'Four', 'Five', 'Six', 'Seven'][len(shipped)]} system files ship" in page
