"""The documentation is true: every Python example of README.md and docs/*.md
runs as written and gives what its text says, every ``nsga-jax`` command shown
parses with the current options, and every link and path it names exists."""

from __future__ import annotations

import math
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from nsga_jax._packaged import packaged

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

WRITTEN_ELSEWHERE = {"docs/own-model.md", "docs/reliability.md"}
"""Pages the documentation links to that are written separately; a link to one
is accepted while it does not exist yet (and checked once it does)."""

SKIP = "<!-- example: not run -->"
"""Put on the line before a ```python fence to keep that block out of the run
(a fragment that cannot run alone)."""


@dataclass
class Example:
    page: Path
    heading: str
    code: str
    output: str | None  # the ```text block right after the example, if any

    @property
    def key(self) -> tuple[str, str]:
        return (self.page.relative_to(ROOT).as_posix(), self.heading)


def _blocks(text: str):
    """(language, body, start offset, end offset) of every fenced block."""
    for m in re.finditer(r"^```([\w-]*)\n(.*?)^```[ \t]*$", text, re.S | re.M):
        yield m.group(1), m.group(2), m.start(), m.end()


def _heading_before(text: str, offset: int) -> str:
    headings = re.findall(r"^#+ .*$", text[:offset], re.M)
    return headings[-1] if headings else ""


def examples() -> list[Example]:
    found = []
    for page in PAGES:
        text = page.read_text()
        blocks = list(_blocks(text))
        for i, (lang, body, start, end) in enumerate(blocks):
            if lang != "python" or text[:start].rstrip().endswith(SKIP):
                continue
            output = None
            if i + 1 < len(blocks) and blocks[i + 1][0] == "text" and not text[end:blocks[i + 1][2]].strip():
                output = blocks[i + 1][1]
            found.append(Example(page, _heading_before(text, start), body, output))
    return found


# ------------------------------------------------------------------ checks
# What each example's variables should hold, by (page, heading of its section).
# The test refuses an example without an entry here.

def _readme_first_example(ns):
    sol = ns["sol"]
    assert sol.stats["failed_steps"] == 0
    assert len(ns["hits"]) == 6
    assert abs(sol.ts[ns["hits"][0]] - math.sqrt(2 * 1.0 / 9.81)) < 1e-3  # within one step of the exact impact


def _python_api_simulate(ns):
    sol = ns["sol"]
    assert sol.stats["failed_steps"] == 0
    assert "tip_force" in sol.observables
    assert float(ns["model"].contacts[0].e) == 0.8 and ns["model"].n_dof == 1


def _python_api_saveat(ns):
    assert ns["every"].ts.shape == (11,)
    np.testing.assert_allclose(np.asarray(ns["every"].ts), np.linspace(0.0, 1.0, 11), atol=1e-12)
    grad = float(ns["jax"].grad(ns["final_height"])(0.8))
    assert math.isfinite(grad) and grad != 0.0


def _python_api_failures(ns):
    assert ns["first"] == ns["Result"].position_max_iter and ns["first"].subproblem == "position"


def _python_api_batches(ns):
    assert [s.n_steps for s in ns["sols"]] == [1500, 750, 375]
    assert all(s.stats["failed_steps"] == 0 for s in ns["sols"])


def _python_api_model(ns):
    sol = ns["sol"]
    assert sol.stats["failed_steps"] == 0
    assert sol.q.min() >= -0.05 - 1e-12  # the stop holds
    assert abs(sol.ts[ns["hits"][0]] - math.asin(0.5) / 10) < 1e-3


def _gradients(ns):
    grad = ns["grads"]
    assert set(grad) == {"E", "e", "velocity"}
    assert all(math.isfinite(float(g)) for g in grad.values())
    assert float(grad["velocity"]) != 0.0 and float(grad["E"]) != 0.0


def _sweep(ns):
    result = ns["result"]
    errors = result.column("error_z")
    assert len(errors) == 6 and np.all(np.isfinite(errors)) and np.all(np.asarray(errors) < 0.1)
    assert (Path("ball_sweep") / "sweep.csv").exists()


def _own_model_from_python(ns):
    sol = ns["sol"]
    assert sol.stats["failed_steps"] == 0 and sol.stats["max_penetration"] <= 1e-8
    assert float(np.abs(ns["sol"].impulse[:, 2]).max()) > 0.0  # the wall was hit
    grad = ns["jax"].grad(ns["x2_at_half_second"])(ns["params"])
    assert float(grad["e"]) == pytest.approx(0.724, rel=1e-2)
    assert float(grad["wall_x"]) == pytest.approx(0.296, rel=1e-2)


def _newtons_cradle(ns):
    sol = ns["sol"]
    assert sol.stats["failed_steps"] == 0
    np.testing.assert_allclose(ns["final"], [0.0, 0.0, 1.0], atol=1e-8)
    np.testing.assert_allclose(sol.observables["momentum"], 0.1, rtol=1e-14)


def _double_pendulum(ns):
    sol = ns["sol"]
    assert sol.stats["failed_steps"] == 0 and sol.stats["max_penetration"] <= 1e-8
    assert ns["error"] < 0.05 and set(ns["reference"]) >= {"theta1", "theta2", "omega1", "omega2"}


def _system_files(ns):
    sol, scene = ns["sol"], ns["scene"]
    assert sol.stats["failed_steps"] == 0 and scene.parameters["contacts.floor.e"] == 0.8
    assert float(sol.observables["floor.gap"].min()) > -1e-10  # it bounced, and never sank in
    assert abs(float(ns["grad"]) - 0.6) < 1e-9
    from nsga_jax.scenes import REGISTRY

    REGISTRY.pop("drop")  # the page's scene stays out of the other tests' registry


def _mechanisms(ns):
    scene = ns["scene"]
    assert scene.parameters["e"] == 1.0
    assert float(np.abs(np.asarray(scene.model.bilateral(scene.q0))).max()) < 1e-12  # the rigid mechanism's state


def _systems(ns):
    sol, model = ns["sol"], ns["model"]
    assert sol.stats["failed_steps"] == 0 and sol.stats["max_bilateral_violation_position"] < 1e-8
    assert float(ns["theta"].min()) == pytest.approx(-math.acos(-0.2), abs=2e-3)  # the tip reached the wall
    assert model.constant_mass and not model.linear_constraints


def _friction(ns):
    sol = ns["sol"]
    assert sol.stats["failed_steps"] == 0
    assert float(sol.q[-1, 0]) == pytest.approx(2.0**2 / (2 * 0.3 * 9.81), abs=1e-5)
    assert abs(float(sol.v[-1, 0])) < 1e-12  # stopped, and at rest


def _impact_instants(ns):
    sol = ns["sol"]
    assert (sol.stats["impacts_at_instants"], sol.stats["instant_fallbacks"]) == (11, 0)
    energy = 0.5 * sol.v[:, 0] ** 2 + 9.81 * sol.q[:, 0]
    assert np.abs(energy / energy[0] - 1.0).max() < 1e-9  # e = 1: every bounce keeps the energy


CHECKS = {
    ("docs/impact-instants.md", "# Impacts at their instants"): _impact_instants,
    ("docs/systems.md", "## A first system"): _systems,
    ("docs/friction.md", "# Coulomb friction"): _friction,
    ("docs/newtons-cradle.md", "## In Python"): _newtons_cradle,
    ("docs/double-pendulum.md", "## In Python"): _double_pendulum,
    ("docs/system-files.md", "## From Python"): _system_files,
    ("docs/mechanisms.md", "# Mechanisms: rigid and flexible bodies with joints and stops"): _mechanisms,
    ("docs/own-model.md", "## 4. From Python"): _own_model_from_python,
    ("README.md", "## A first example"): _readme_first_example,
    ("docs/python-api.md", "## Running a model: `integrate` and `simulate`"): _python_api_simulate,
    ("docs/python-api.md", "## Output control: `SaveAt`"): _python_api_saveat,
    ("docs/python-api.md", "## Batches"): _python_api_batches,
    ("docs/python-api.md", "## Failures"): _python_api_failures,
    ("docs/python-api.md", "## Writing a model"): _python_api_model,
    ("docs/gradients.md", "## Gradients through whole trajectories"): _gradients,
    ("docs/sweeps-and-devices.md", "## Sweeps"): _sweep,
}

EXAMPLES = examples()


def test_every_example_has_a_check_and_every_check_an_example():
    keys = [e.key for e in EXAMPLES]
    assert len(keys) == len(set(keys)), "one example per section, so that each has its own check"
    assert set(keys) == set(CHECKS), (set(keys) ^ set(CHECKS))
    assert ("README.md", "## A first example") in keys


@pytest.mark.timeout(300)
@pytest.mark.parametrize("example", EXAMPLES, ids=[f"{e.key[0]}: {e.key[1].lstrip('# ')}" for e in EXAMPLES])
def test_example_runs_as_written(example, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # examples that write files write them here, and read configs and example
    # scene files (configs/..., examples/...) from the package, as from any folder
    namespace: dict = {"__name__": "__example__"}
    exec(compile(example.code, str(example.page), "exec", dont_inherit=True), namespace)
    printed = capsys.readouterr().out
    if example.output is not None:
        assert printed == example.output, "the output shown under the example is what it prints"
    CHECKS[example.key](namespace)


# ---------------------------------------------------------- shell commands

def _shell_commands(text: str) -> list[list[str]]:
    """Every ``nsga-jax ...`` command line of the bash and console blocks."""
    commands = []
    for lang, body, _, _ in _blocks(text):
        if lang not in ("bash", "console", "sh"):
            continue
        joined = re.sub(r"\\\n\s*", " ", body)
        for line in joined.splitlines():
            line = line.strip()
            if lang == "console":
                if not line.startswith("$ "):
                    continue
                line = line[2:]
            words = shlex.split(line, comments=True)
            while words and re.match(r"^[A-Z_]+=", words[0]):  # environment variables
                words = words[1:]
            if "&&" in words:
                words = words[words.index("&&") + 1:]
            if words and words[0] == "nsga-jax":
                commands.append(words[1:])
    return commands


COMMANDS = [(page.relative_to(ROOT).as_posix(), words) for page in PAGES for words in _shell_commands(page.read_text())]


def test_the_pages_show_commands():
    assert len(COMMANDS) > 20
    assert ("README.md", ["run", "impacting_bar"]) in COMMANDS


@pytest.mark.parametrize("page, words", COMMANDS, ids=[f"{p}: nsga-jax {' '.join(w)}"[:100] for p, w in COMMANDS])
def test_command_parses_with_the_current_options(page, words):
    from nsga_jax._cli import command_parser
    from nsga_jax.scenes import load_scene, parse_override

    args = command_parser().parse_args(words)  # an unknown option exits with status 2
    scene = getattr(args, "scene", None)
    if scene is None or args.command == "config":
        return
    path = packaged(scene) or ROOT / scene  # configs/... and examples/...: from the package, from any folder
    if scene.endswith(".toml"):
        if not path.exists():
            pytest.skip(f"{scene} is a file the page tells the reader to write")
        scene = path
    overrides = dict(parse_override(s) for s in getattr(args, "set", []))
    if args.command == "run":
        for key in ("h", "t_end", "rho_inf", "scheme", "dtype", "record_every"):
            if getattr(args, key, None) is not None:
                overrides[key] = getattr(args, key)
    load_scene(scene, overrides)  # unknown keys and values out of range raise ConfigError


# ------------------------------------------------------- links and paths

def _anchors(text: str) -> set[str]:
    """The anchors a git forge gives the headings of a Markdown page."""
    anchors, seen = set(), {}
    in_code = False
    for line in text.splitlines():
        if line.startswith("```"):
            in_code = not in_code
        if in_code or not re.match(r"^#+ ", line):
            continue
        title = re.sub(r"[`*]", "", line.lstrip("#").strip()).lower()
        slug = re.sub(r"[^\w\- ]", "", title).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        anchors.add(slug if n == 0 else f"{slug}-{n}")
    return anchors


def _links(page: Path):
    text = page.read_text()
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)  # not in code blocks
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if not re.match(r"^[a-z]+:", target):
            yield target


LINKS = [(page.relative_to(ROOT).as_posix(), target) for page in PAGES for target in _links(page)]


@pytest.mark.parametrize("page, target", LINKS, ids=[f"{p} -> {t}" for p, t in LINKS])
def test_relative_link_resolves(page, target):
    path, _, anchor = target.partition("#")
    source = ROOT / page
    dest = (source.parent / path).resolve() if path else source
    rel = dest.relative_to(ROOT).as_posix() if dest.is_relative_to(ROOT) else str(dest)
    if not dest.exists():
        assert rel in WRITTEN_ELSEWHERE, f"{target} does not exist"
        return
    if anchor:
        assert anchor in _anchors(dest.read_text()), f"no heading #{anchor} in {rel}"


def test_every_page_of_docs_is_in_the_index():
    index = (ROOT / "docs" / "README.md").read_text()
    for page in (ROOT / "docs").glob("*.md"):
        if page.name != "README.md":
            assert f"]({page.name})" in index, page.name
    for name in WRITTEN_ELSEWHERE:
        assert f"]({Path(name).name})" in index


def test_paths_named_in_the_pages_exist():
    named = set()
    for page in PAGES:
        pattern = r"\b((?:experiments|configs|examples|tests|nsga_jax|docs)/[\w./-]*\w\.(?:py|toml|md|csv|json|png))\b"
        named |= set(re.findall(pattern, page.read_text()))
    assert named
    missing = sorted(p for p in named if not (ROOT / p).exists() and packaged(p) is None and p not in WRITTEN_ELSEWHERE)
    assert not missing, missing

