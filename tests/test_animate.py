"""``nsga-jax animate``: a finished run's folder drawn as a GIF and a
self-contained HTML page. The drawing of every built-in scene and system
file (bodies, joints, contacts, planes) from the model's structure; the
GIF's frames; the page's data and its independence from the network; the
page in a real headless browser (Chromium, where installed); the command's
refusals."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from nsga_jax._animate.command import write_animation
from nsga_jax._animate.frames import Animation, animation_of, frame_rows
from nsga_jax._animate.html import CONTROLS_HEIGHT, page, read_data
from nsga_jax._animate.outlines import convex_hull, hex_outer_faces, inertia_box, planar_outline
from nsga_jax._animate.run_folder import RecordedRun, load_run
from nsga_jax._animate.screen import STYLES, View, fit, frame_shapes, project
from nsga_jax._cli import main
from nsga_jax.scenes import REGISTRY, load_scene

ROOT = Path(__file__).resolve().parents[1]
BUILT_IN = sorted(REGISTRY)
SYSTEM_FILES = sorted((ROOT / "nsga_jax" / "configs" / "systems").glob("*.toml"))


def fake_run(folder: Path, scene: str, overrides: dict | None = None, *, rows: int = 7,
             move: dict[int, float] | None = None) -> Path:
    """A run folder as ``nsga-jax run`` leaves it, without running: run.json
    and trajectory.npz with ``rows`` records that start at the scene's
    initial state and move the coordinates ``move`` (index: step per record)."""
    import jax

    built = load_scene(scene, overrides)
    model = built.model
    q = np.tile(built.q0, (rows, 1))
    for index, step in (move or {}).items():
        q[:, index] += step * np.arange(rows)
    gap = np.asarray(jax.vmap(model.unilateral)(q)).reshape(rows, model.n_unilateral)
    impulse = np.zeros((rows, model.n_constraints))
    impulse[:, model.n_bilateral:] = np.where(gap <= 1e-9, 1e-3, 0.0)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "run.json").write_text(json.dumps({"command": "run", "scene": scene, "parameters": built.parameters,
                                                 "solver": built.solver, "cwd": str(Path.cwd())}))
    np.savez(folder / "trajectory.npz", t=np.linspace(0.0, 0.1, rows), q=q, v=np.zeros_like(q), impulse=impulse,
             gap=gap)
    return folder


def recorded(scene: str, overrides: dict | None = None) -> RecordedRun:
    """A run of two records at the scene's initial state."""
    built = load_scene(scene, overrides)
    model = built.model
    return RecordedRun(Path("."), built.name, model, np.array([0.0, 1e-3]), np.tile(built.q0, (2, 1)),
                       np.zeros((2, model.n_constraints)), np.ones((2, model.n_unilateral)), 1e-3)


def kinds(animation: Animation) -> Counter:
    return Counter(item.kind for item in animation.items)


def check_drawing(animation: Animation, model) -> None:
    """What every drawing must be: finite points, a box of some size, every
    body drawn, a plane for each plane contact, shapes to draw in every frame."""
    assert np.all(np.isfinite(animation.moving)) and np.all(np.isfinite(animation.fixed))
    assert animation.size > 0
    drawn = {item.part for item in animation.items}
    assert {f"bodies.{name}" for name in model.body_names} <= drawn
    for contact, name in zip(model.contacts, model.contact_names):
        if type(contact).__name__ == "PlaneContact":
            assert any(item.kind == "ground" and item.part.startswith("contacts.") for item in animation.items), name
    for frame in range(animation.n_frames):
        assert frame_shapes(animation, frame, View(), fit(animation, View()))


# ------------------------------------------------------------ geometry


EXPECTED = {  # kinds of items each built-in scene draws, at its defaults
    "bouncing_ball": {"ball": 1, "contact": 1, "ground": 1},
    "box_stack": {"body": 3, "contact": 20, "ground": 1},
    "double_pendulum": {"body": 2, "pivot": 1, "joint": 1, "contact": 1, "ground": 1},
    "flexible_appendage": {"body": 1, "spoke": 1, "beam": 1, "pivot": 1, "joint": 1, "contact": 1, "ground": 1},
    "flexible_cube": {"solid": 150, "contact": 36, "ground": 1, "shadow": 150},
    "flexible_pendulum": {"beam": 1, "pivot": 1, "contact": 1, "ground": 1},
    "impacting_bar": {"bar": 1, "tick": 1, "contact": 1, "ground": 1},
    "incline": {"body": 1, "contact": 2, "ground": 1},
    "newtons_cradle": {"ball": 5, "contact": 4},
    "rigid_box": {"body": 6, "contact": 8, "ground": 1, "shadow": 6},
    "rigid_pendulum": {"ball": 1, "rod": 1, "pivot": 1, "contact": 1, "ground": 1},
    "rocking_block": {"body": 1, "contact": 2, "ground": 1},
    "slider_crank": {"body": 1, "beam": 1, "ball": 1, "pivot": 1, "joint": 3, "contact": 1, "guide": 1, "ground": 1},
}


def test_every_built_in_scene_has_its_expected_drawing():
    assert sorted(EXPECTED) == BUILT_IN, "a new built-in scene: say what its drawing holds"


@pytest.mark.parametrize("scene", BUILT_IN)
def test_every_built_in_scene_is_drawn(scene):
    run = recorded(scene)
    animation = animation_of(run)
    check_drawing(animation, run.model)
    found = kinds(animation)
    assert {k: found[k] for k in EXPECTED[scene]} == EXPECTED[scene], dict(found)


def test_box_stack_in_3d_is_drawn_as_boxes_with_shadows():
    run = recorded("box_stack", {"dim": 3})
    animation = animation_of(run)
    check_drawing(animation, run.model)
    assert animation.dim == 3 and kinds(animation)["body"] == 18 and kinds(animation)["shadow"] == 18
    np.testing.assert_allclose(animation.up, [0.0, 0.0, 1.0])


@pytest.mark.parametrize("path", SYSTEM_FILES, ids=lambda p: p.name)
def test_every_system_file_is_drawn(path, scene_registry):
    run = recorded(str(path))
    check_drawing(animation_of(run), run.model)


def test_a_block_is_the_rectangle_of_its_corners_and_leans_as_it_does():
    """rocking_block: the block (0.2 m × 0.6 m) from its two bottom corners
    mirrored through its centre, tilted by the scene's 0.15 rad, its pivot
    corner on the floor y = 0, the floor horizontal."""
    animation = animation_of(recorded("rocking_block"))
    (block,) = [item for item in animation.items if item.kind == "body"]
    corners = animation.moving[0, list(block.points), :2]
    sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    np.testing.assert_allclose(sorted(sides), [0.2, 0.2, 0.6, 0.6], rtol=1e-12)
    edge = corners[np.argmax(sides)] - corners[np.argmax(sides) - 1]
    assert abs(abs(np.arctan2(edge[0], edge[1])) - 0.15) < 1e-9 or abs(abs(np.arctan2(edge[1], edge[0])) - 0.15) \
        < 1e-9
    assert abs(corners[:, 1].min()) < 1e-12
    (floor,) = [item for item in animation.items if item.kind == "ground"]
    line = animation.frame_points(0)[list(floor.points)]
    np.testing.assert_allclose(line[:, 1], 0.0, atol=1e-12)


def test_a_line_system_is_drawn_across_or_up_the_page():
    """A system on a line: the bar along x (no gravity), the falling ball up y (gravity along its line)."""
    bar = animation_of(recorded("impacting_bar"))
    (line,) = [item for item in bar.items if item.kind == "bar"]
    points = bar.moving[0, list(line.points)]
    np.testing.assert_allclose(points[:, 1:], 0.0)
    np.testing.assert_allclose(points[[0, -1], 0], [-10.0, 0.0])
    ball = animation_of(recorded("bouncing_ball"))
    (dot,) = [item for item in ball.items if item.kind == "ball"]
    np.testing.assert_allclose(ball.moving[0, dot.points[0]], [0.0, 1.0, 0.0])


def test_balls_take_the_radius_of_their_contacts():
    animation = animation_of(recorded("newtons_cradle"))
    balls = [item for item in animation.items if item.kind == "ball"]
    assert [item.radius for item in balls] == [0.01] * 5
    contacts = [item for item in animation.items if item.kind == "contact"]
    between = animation.moving[0, [item.points[0] for item in contacts], 0]
    np.testing.assert_allclose(np.diff(between), 0.021)  # 2 r + gap apart, on the touching surfaces


def test_planar_outlines_follow_the_anchors_and_the_inertia():
    rod, round_ = planar_outline(1.0, 1.0 / 12.0, _features([[0.0, 0.5], [0.0, -0.5]]))
    assert not round_ and np.ptp(rod[:, 1]) == pytest.approx(1.0) and np.ptp(rod[:, 0]) == pytest.approx(0.05)
    hub, round_ = planar_outline(10.0, 0.5 * 10.0 * 0.2**2, _features([[0.2, 0.0]]))
    assert round_ and np.linalg.norm(hub, axis=1) == pytest.approx(np.full(len(hub), 0.2))
    box, round_ = planar_outline(1.0, 1.0, _features([[-0.1, -0.05], [0.1, -0.05]]))
    assert not round_ and sorted(map(tuple, np.round(box, 12))) == [(-0.1, -0.05), (-0.1, 0.05), (0.1, -0.05),
                                                                    (0.1, 0.05)]
    ball, round_ = planar_outline(1.0, 0.004, _features([], radius=0.1))
    assert round_ and np.linalg.norm(ball, axis=1) == pytest.approx(np.full(len(ball), 0.1))


def _features(anchors, radius=0.0):
    from nsga_jax._animate.outlines import Features

    return Features([np.asarray(a, float) for a in anchors], radius)


def test_a_3d_body_is_the_box_of_its_inertia_and_a_mesh_its_outer_faces():
    from nsga_jax._elements.hex8 import structured_hex_mesh
    from nsga_jax._elements.rigid_body import box_inertia

    vertices = inertia_box(2.0, np.asarray(box_inertia(2.0, np.array([0.1, 0.2, 0.3]))))
    assert sorted(np.ptp(vertices, axis=0)) == pytest.approx([0.1, 0.2, 0.3])
    _, connectivity = structured_hex_mesh((1.0, 1.0, 1.0), (2, 3, 4))
    assert len(hex_outer_faces(connectivity)) == 2 * (2 * 3 + 3 * 4 + 2 * 4)
    assert len(convex_hull(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], float))) == 4


def test_frames_are_spread_over_the_run_and_keep_its_ends():
    assert frame_rows(1001, 120).tolist()[:3] == [0, 8, 17] and frame_rows(1001, 120)[-1] == 1000
    assert len(frame_rows(1001, 120)) == 120 and frame_rows(5, 120).tolist() == [0, 1, 2, 3, 4]


def test_records_of_failed_steps_are_left_out(tmp_path):
    """A run kept going past failed steps (``--no-throw``) may hold NaN: those records are not drawn."""
    folder = fake_run(tmp_path / "run", "rocking_block", rows=6, move={0: 0.01})
    with np.load(folder / "trajectory.npz") as stored:
        data = dict(stored)
    data["q"][3] = np.nan
    data["gap"][3] = np.nan
    data["impulse"][3] = np.nan
    np.savez(folder / "trajectory.npz", **data)
    animation = animation_of(load_run(folder), forces=True)
    assert animation.n_frames == 5 and 0.06 not in animation.times.round(2)
    assert np.all(np.isfinite(animation.moving)) and json.dumps(read_data(page(animation)))


# ----------------------------------------------------------------- GIF


def test_the_gif_has_its_frames_drawn_and_moving(tmp_path):
    from PIL import Image

    folder = fake_run(tmp_path / "run", "rocking_block", rows=9, move={0: 0.02, 2: -0.03})
    paths = write_animation(folder, formats="gif", max_frames=5, fps=10)
    assert set(paths) == {"gif"} and not (folder / "animation.html").exists()
    image = Image.open(paths["gif"])
    assert image.n_frames == 5 and image.size == (640, 480)
    frames = []
    for k in range(image.n_frames):
        image.seek(k)
        frames.append(np.asarray(image.convert("RGB")).astype(int))
    body = np.array([int(STYLES["body"].fill[i:i + 2], 16) for i in (1, 3, 5)])
    for frame in frames:
        assert (np.abs(frame - 255).sum(axis=-1) > 30).mean() > 0.02  # not blank
        assert (np.abs(frame - body).sum(axis=-1) < 12).sum() > 2000  # the block, in its colour
    assert np.abs(frames[0] - frames[-1]).sum(axis=-1).astype(bool).sum() > 1000  # it moved


# ---------------------------------------------------------------- HTML


def test_the_page_carries_everything_and_its_data_round_trips(tmp_path):
    folder = fake_run(tmp_path / "run", "slider_crank", rows=5, move={2: 0.1})
    run = load_run(folder)
    animation = animation_of(run, forces=True)
    text = page(animation)
    assert "http://" not in text and "https://" not in text and "//" + "cdn" not in text
    assert "<link" not in text and " src=" not in text and "@import" not in text and "url(" not in text
    data = read_data(text)
    assert data["title"] == "slider_crank" and data["dim"] == 2
    assert [item["kind"] for item in data["items"]] == [item.kind for item in animation.items]
    for item, entry in zip(animation.items, data["items"]):
        points = entry.get("points") or list(range(entry["range"][0], entry["range"][0] + entry["range"][1]))
        assert tuple(points) == item.points
    tolerance = 1e-4 * animation.size
    np.testing.assert_allclose(np.reshape(data["moving"], animation.moving.shape), animation.moving, atol=tolerance)
    np.testing.assert_allclose(np.reshape(data["fixed"], animation.fixed.shape), animation.fixed, atol=tolerance)
    np.testing.assert_allclose(data["times"], animation.times)
    for index in range(len(animation.items)):
        flags = data["active"].get(str(index), "1" * animation.n_frames)
        assert [c == "1" for c in flags] == animation.active[:, index].tolist()
    assert data["styles"]["body"]["fill"] == STYLES["body"].fill


def test_a_page_title_cannot_close_the_data_script():
    animation = animation_of(recorded("rocking_block"))
    hostile = Animation("</script><b>x", *[getattr(animation, f) for f in
                                           ("dim", "up", "items", "times", "moving", "fixed", "active", "focus")])
    text = page(hostile)
    assert "</script><b>" not in text and read_data(text)["title"] == "</script><b>x"


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def chromium(*arguments: str) -> str:
    """Run headless Chromium (its console on stderr); returns stdout, after
    checking that no script error reached the console."""
    command = [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
               "--enable-logging=stderr", "--v=0", *arguments]
    done = subprocess.run(command, check=True, capture_output=True, text=True, timeout=120)
    assert "Uncaught" not in done.stderr, done.stderr
    return done.stdout


def screenshot(html: Path, png: Path, frame: int, view: str = "") -> np.ndarray:
    """Chromium's picture (600, 800, 3) of the page at ``frame`` (seen from ``view``, ``"A,E"`` [deg], in 3D)."""
    from PIL import Image

    turned = f"&view={view}" if view else ""
    chromium("--force-device-scale-factor=1", f"--screenshot={png}", "--window-size=800,600",
             f"{html.resolve().as_uri()}#frame={frame}{turned}")
    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def colour_mask(picture: np.ndarray, colour: str, tolerance: int = 12) -> np.ndarray:
    rgb = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])
    return np.abs(picture - rgb).sum(axis=-1) < tolerance


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium on this machine (apt-get install chromium)")
def test_the_page_draws_the_block_where_the_view_puts_it(tmp_path):
    """The page in headless Chromium at 800 × 600, paused at frame 0: the
    block in its colour, centred where the Python view (the same fit as the
    player's) puts it, on the canvas above the controls."""
    folder = fake_run(tmp_path / "run", "rocking_block", rows=5, move={2: -0.05})
    paths = write_animation(folder, formats="html")
    picture = screenshot(paths["html"], tmp_path / "shot.png", frame=0)
    assert picture.shape == (600, 800, 3)
    assert (np.abs(picture - 255).sum(axis=-1) > 30).mean() > 0.02
    block = colour_mask(picture, STYLES["body"].fill)
    assert block.sum() > 5000
    animation = animation_of(load_run(folder))
    view = View(width=800, height=600 - CONTROLS_HEIGHT)
    (item,) = [i for i in animation.items if i.kind == "body"]
    xy, _ = project(animation.moving[0, list(item.points)], animation, view)
    corners = fit(animation, view).pixels(xy)
    ys, xs = np.nonzero(block)
    assert abs(xs.mean() - corners[:, 0].mean()) < 4 and abs(ys.mean() - corners[:, 1].mean()) < 4
    assert xs.min() >= corners[:, 0].min() - 3 and xs.max() <= corners[:, 0].max() + 3
    ground = colour_mask(picture, STYLES["ground"].stroke, 40)
    assert ground[int(corners[:, 1].max()) - 3: int(corners[:, 1].max()) + 4].sum() > 300  # the floor under it


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium on this machine (apt-get install chromium)")
@pytest.mark.parametrize("turn", ["", "150,60"], ids=["first view", "turned"])
def test_the_page_draws_a_3d_solid_on_its_floor_from_any_side(tmp_path, turn):
    """The cube above its floor, where the Python view puts it, in the first
    view and turned (``#view=``: what dragging does)."""
    import math

    folder = fake_run(tmp_path / "run", "flexible_cube", {"divisions": 2}, rows=3)
    paths = write_animation(folder, formats="html")
    animation = animation_of(load_run(folder))
    nodes = sorted({i for item in animation.items if item.kind == "solid" for i in item.points})
    picture = screenshot(paths["html"], tmp_path / "shot.png", frame=2, view=turn)[:600 - CONTROLS_HEIGHT]
    blue = (picture[..., 2] > picture[..., 0] + 60) & (picture[..., 2] > 120)  # the canvas: not the slider
    ys, xs = np.nonzero(blue)
    assert blue.sum() > 2000
    angles = [math.radians(float(a)) for a in turn.split(",")] if turn else [View().azimuth, View().elevation]
    view = View(800, 600 - CONTROLS_HEIGHT, *angles)
    xy, _ = project(animation.moving[2, nodes], animation, view)
    centre = fit(animation, view).pixels(xy).mean(axis=0)
    assert abs(xs.mean() - centre[0]) < 4 and abs(ys.mean() - centre[1]) < 4, (turn, xs.mean(), ys.mean(), centre)
    floor = colour_mask(picture, STYLES["ground"].fill)
    assert floor.sum() > 20000 and np.nonzero(floor)[0].mean() > ys.mean()  # the floor below the cube


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium on this machine (apt-get install chromium)")
def test_the_page_plays_by_itself_and_opens_paused_where_asked(tmp_path):
    import re

    folder = fake_run(tmp_path / "run", "rigid_pendulum", rows=40, move={0: 0.001})
    html = write_animation(folder, formats="html", fps=20)["html"].resolve().as_uri()

    def state(dom: str) -> tuple[str, int]:
        button = re.search(r'<button id="play"[^>]*>(\w+)</button>', dom)
        shown = re.search(r'<span id="time">t = [0-9.]+ s +\((\d+)/40\)</span>', dom)
        assert button and shown, dom[-600:]
        return button.group(1), int(shown.group(1))

    playing, frame = state(chromium("--virtual-time-budget=1000", "--dump-dom", html))
    assert playing == "Pause" and 15 <= frame <= 25  # 20 frames per second for a second
    assert state(chromium("--virtual-time-budget=1000", "--dump-dom", html + "#frame=7")) == ("Play", 8)


# ------------------------------------------------------------- command


def test_animate_writes_both_files_into_the_run_folder(tmp_path, capsys):
    folder = fake_run(tmp_path / "run", "double_pendulum", rows=4, move={2: 0.1, 5: -0.1})
    assert main(["animate", str(folder), "--max-frames", "3", "--forces"]) == 0
    out = capsys.readouterr().out
    assert "animation.gif" in out and "animation.html" in out
    assert (folder / "animation.gif").is_file() and (folder / "animation.html").is_file()


def test_a_system_file_run_is_redrawn_from_another_folder(tmp_path, monkeypatch, scene_registry):
    """run.json names a system file by a relative path; the animation finds it from the run's cwd."""
    monkeypatch.chdir(ROOT)
    folder = fake_run(tmp_path / "run", "configs/systems/spring_chain.toml", rows=3, move={0: 0.05})
    monkeypatch.chdir(tmp_path)
    assert write_animation(folder, formats="html", max_frames=2)["html"].is_file()


@pytest.mark.parametrize("argv, message", [
    (["animate", "{tmp}/nowhere"], "does not exist"),
    (["animate", "{tmp}/empty"], "holds no finished run: no trajectory.npz"),
    (["animate", "{tmp}/empty", "--fps", "0"], "--fps [frames/s] must be in (0, 50]"),
    (["animate", "{tmp}/empty", "--fps", "nan"], "--fps [frames/s] must be finite"),
    (["animate", "{tmp}/empty", "--max-frames", "0"], "--max-frames must be an integer >= 1"),
    (["animate", "{tmp}/empty", "--format", "png"], "invalid choice: 'png'"),
    (["animate", "{tmp}/file.txt"], "is a file, not a folder"),
])
def test_bad_input_is_one_line_naming_it(tmp_path, capsys, argv, message):
    (tmp_path / "empty").mkdir()
    (tmp_path / "file.txt").write_text("x")
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err


def test_a_folder_of_another_command_is_refused(tmp_path, capsys):
    folder = fake_run(tmp_path / "run", "rocking_block", rows=2)
    record = json.loads((folder / "run.json").read_text())
    (folder / "run.json").write_text(json.dumps({**record, "command": "sweep"}))
    assert main(["animate", str(folder)]) == 2
    assert "animate draws the folders of `nsga-jax run`" in capsys.readouterr().err


@pytest.mark.slow
def test_a_real_run_with_animate_writes_its_animation(tmp_path, capsys):
    """``nsga-jax run ... --animate``: the run, then its GIF and page, from the folder it wrote."""
    out = tmp_path / "rb"
    assert main(["run", "rocking_block", "--t-end", "0.3", "--out", str(out), "--quiet", "--animate"]) == 0
    assert "animation.gif" in capsys.readouterr().out
    from PIL import Image

    assert Image.open(out / "animation.gif").n_frames == 120
    assert len(read_data((out / "animation.html").read_text())["times"]) == 120
