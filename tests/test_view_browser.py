"""``linkopt view``'s page in headless Chromium (issue 42), driven by Playwright: moving
the motor sliders puts the drawn end-effector where ``linkopt fk`` puts it (both
designs of a run folder's page), a failed configuration is shown as failed and draws
no mechanism, a screenshot has the mechanism's pixels, and the page logs no console
error. One page for the module (a five-bar run folder).

Skipped, with the reason, when no Chromium executable is found, unless
``LINKOPT_REQUIRE_BROWSER=1`` (CI sets it), which makes a missing browser a failure.
``LINKOPT_DOCS_SCREENSHOT=1`` saves the page's screenshot as
``docs/figures/view_five_bar.png``.
"""

import io
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._cli.main import main

ROOT = Path(__file__).resolve().parent.parent
FIVE_BAR = ROOT / "mechanisms" / "five_bar.toml"
ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
RESOLUTION = 15


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser"):
        found = shutil.which(name)
        if found:
            return found
    return None


def _missing(reason: str):
    if os.environ.get("LINKOPT_REQUIRE_BROWSER") == "1":
        pytest.fail(f"LINKOPT_REQUIRE_BROWSER=1 but {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    """A run folder of the five-bar (initial design moved off the file's) and its
    page."""
    folder = tmp_path_factory.mktemp("run")
    mech = linkopt.load(str(FIVE_BAR))
    initial = mech.design.p0 + 0.3 * (mech.design.upper - mech.design.p0)
    shutil.copy(FIVE_BAR, folder / "optimized.toml")
    summary = {"initial_design": dict(zip(mech.design.names, initial.tolist()))}
    (folder / "summary.json").write_text(json.dumps(summary))
    assert main(["view", str(folder), "--resolution", str(RESOLUTION)]) == 0
    return folder, {"initial": initial, "optimised": mech.design.p0}


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module (Playwright's sync API allows one loop
    per thread, so the pages share it)."""
    executable = _chromium()
    if executable is None:
        _missing("no chromium executable on PATH (apt-get install chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _missing(
            "playwright's Python package is not installed (pip install playwright)"
        )
    with sync_playwright() as play:
        chromium = play.chromium.launch(executable_path=executable, args=ARGS)
        yield chromium
        chromium.close()


def _open(browser, path: Path):
    """A tab on the page at ``path``, once drawn, and the list its errors go to."""
    tab = browser.new_page(viewport={"width": 1280, "height": 800})
    errors = []
    tab.on("console", lambda m: errors.append(m.text) if m.type == "error" else 0)
    tab.on("pageerror", lambda e: errors.append(str(e)))
    tab.goto(path.as_uri())
    tab.wait_for_selector("body[data-ready='1']", timeout=120_000)
    return tab, errors


@pytest.fixture(scope="module")
def page(browser, run_folder):
    folder, _ = run_folder
    tab, errors = _open(browser, folder / "view.html")
    yield tab, errors
    tab.close()


def _state(tab) -> dict:
    return tab.evaluate(
        "async () => { await linkoptView.idle(); return linkoptView.state(); }"
    )


def _move(tab, index) -> dict:
    """Move each motor's slider to its grid ``index`` as a user drags it."""
    for m, i in enumerate(index):
        tab.locator(f"#motor-{m}").evaluate(
            "(el, v) => { el.value = v; el.dispatchEvent(new Event('input')); }", i
        )
    return _state(tab)


def _fk_point(capsys, folder, motors, design) -> np.ndarray:
    capsys.readouterr()
    code = main(
        [
            "fk",
            str(folder / "optimized.toml"),
            "--motors",
            ",".join(f"{v:.17g}" for v in motors),
            "--design",
            ",".join(f"{v:.17g}" for v in design),
            "--json",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    return np.array(json.loads(out)["points"]["ee"])


def test_sliders_put_the_end_effector_where_fk_does(page, run_folder, capsys):
    tab, errors = page
    folder, designs = run_folder
    rest = RESOLUTION // 2
    scale = linkopt.load(str(FIVE_BAR)).length_scale
    for k, label in enumerate(("initial", "optimised")):
        tab.select_option("#design", str(k))
        checked = 0
        for step in [(3, 2), (-4, 1), (2, -3), (5, 5)]:
            state = _move(tab, [rest + step[0], rest + step[1]])
            assert state["label"] == label and state["index"] == [
                rest + step[0],
                rest + step[1],
            ]
            if not state["feasible"]:
                continue
            want = _fk_point(capsys, folder, state["motors"], designs[label])
            drawn = np.array(state["points"]["ee"])
            assert np.linalg.norm(drawn - want) <= 1e-6 * scale, (label, step)
            assert state["drawnSegments"] > 0
            checked += 1
        assert checked >= 3
    assert errors == []


def test_a_click_on_the_motor_map_moves_both_motors(page):
    """The motor-space map is a 2-D pad: a click on a cell sets both sliders."""
    tab, errors = page
    tab.select_option("#design", "0")
    rest = RESOLUTION // 2
    _move(tab, [rest, rest])
    want = [rest + 3, rest - 2]
    x, y = tab.evaluate(
        """([a, b]) => {
            const div = document.getElementById("linkopt-map"), L = div._fullLayout;
            const box = div.getBoundingClientRect();
            const axes = linkoptView.data.designs[0].axes;
            return [box.left + L.xaxis._offset + L.xaxis.l2p(axes[0][a]),
                    box.top + L.yaxis._offset + L.yaxis.l2p(axes[1][b])];
        }""",
        want,
    )
    tab.mouse.move(x - 2, y - 2)  # plotly's click takes the cell hovered last
    tab.mouse.move(x, y)
    tab.mouse.click(x, y)
    tab.wait_for_function(
        "([a, b]) => linkoptView.state().index.join() === [a, b].join()", arg=want
    )
    state = _state(tab)
    assert state["index"] == want
    assert [tab.locator(f"#motor-{m}").input_value() for m in (0, 1)] == [
        str(v) for v in want
    ]
    assert errors == []


def test_failed_cells_shown_as_failed_and_a_screenshot_not_blank(page):
    tab, errors = page
    tab.select_option("#design", "1")
    failed = tab.evaluate("linkoptView.failedCells()")
    assert failed, "the grid's window reaches past the rest branch"
    index = tab.evaluate(f"linkoptView.cellIndex({failed[0]})")
    state = _move(tab, index)
    assert not state["feasible"] and state["f_sing"] is None
    assert state["drawnSegments"] == 0 and state["points"] == {}
    assert "FAILED" in state["status"]
    assert tab.locator("#status.failed").count() == 1
    rest = RESOLUTION // 2
    state = _move(tab, [rest, rest])
    assert state["feasible"] and "FAILED" not in state["status"]
    # the end-effector's trace has a dot per reached cell; the target box is the
    # outputs' range (x in [-40, 40], y in [15, 80])
    traces = tab.evaluate(
        """() => document.getElementById("linkopt-scene").data.map(t => [
               t.name, t.x.filter(v => v !== null), t.y.filter(v => v !== null)])"""
    )
    traces = {name: (np.array(x), np.array(y)) for name, x, y in traces}
    reached = tab.evaluate("linkoptView.data.designs[1].states.filter(s => s).length")
    assert len(traces["ee trace (colour: log10 f_sing)"][0]) == reached
    x, y = traces["target range"]
    assert (x.min(), x.max(), y.min(), y.max()) == (-40, 40, 15, 80)
    tab.mouse.move(1, 1)  # no hover label left by another test
    tab.wait_for_timeout(300)
    shot = tab.locator("#linkopt-scene").screenshot()
    if os.environ.get("LINKOPT_DOCS_SCREENSHOT") == "1":
        tab.screenshot(path=str(ROOT / "docs" / "figures" / "view_five_bar.png"))
    from PIL import Image

    pixels = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB")).reshape(-1, 3)
    bodies = tab.evaluate("linkoptView.data.designs[1].bodies.map(b => b.colour)")
    for colour in bodies:
        rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
        near = np.count_nonzero(np.max(np.abs(pixels.astype(int) - rgb), axis=1) < 40)
        assert near > 50, colour  # each link's capsule is drawn
    assert errors == []


@pytest.fixture(scope="module")
def curve_page(browser, tmp_path_factory):
    """The page of a file with a ``[synthesis]`` path (the shipped four-bar)."""
    out = tmp_path_factory.mktemp("curve") / "view.html"
    path = ROOT / "mechanisms" / "four_bar_path.toml"
    assert main(["view", str(path), "--resolution", "9", "--out", str(out)]) == 0
    tab, errors = _open(browser, out)
    yield tab, errors
    tab.close()


def test_the_target_points_and_the_traced_curve_are_drawn(curve_page):
    """The drawn targets and traced curve are the page data's, which
    ``tests/test_view.py`` checks against the engine."""
    tab, errors = curve_page
    drawn = tab.evaluate(
        "async () => { await linkoptView.idle(); const d = linkoptView.data.designs[0];"
        " const t = document.getElementById('linkopt-scene').data;"
        " return { curve: d.curve, traces: t.filter(x => x.name.includes(d.curve.name"
        " + ':')).map(x => ({ name: x.name, x: x.x, y: x.y, z: x.z })) }; }"
    )
    curve = drawn["curve"]
    by_name = {t["name"].split(": ")[1]: t for t in drawn["traces"]}
    assert set(by_name) == {"traced over the cycle", "targets (in order)"}
    targets = by_name["targets (in order)"]
    np.testing.assert_allclose(
        np.c_[targets["x"], targets["y"], targets["z"]], curve["targets"], atol=0
    )
    traced = by_name["traced over the cycle"]
    want = [p if p is not None else [None] * 3 for p in curve["traced"]]
    assert [list(p) for p in zip(traced["x"], traced["y"], traced["z"])] == want
    assert len(curve["traced"]) >= 360
    status = tab.locator("#status").inner_text()
    assert curve["defect"] is not None  # the file's design misses its targets
    assert status.endswith(f"Cycle: {curve['defect']}")
    assert errors == []
