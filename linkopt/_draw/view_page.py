"""The browser view's HTML and script (:mod:`.view`): plotly.js and the page's data
are inlined, nothing is fetched.

The script keeps one state (``design``, one grid index per motor) and draws it: the
bodies posed by the cell's state (each capsule and joint turned by its body's
quaternion, ``wxyz``, and moved to its origin), the named points, the motor-space map
with the cell marked. A failed cell draws no mechanism and says so. Tests and users
read the page's state through ``window.linkoptView`` (``state()``, ``setCell``,
``setDesign``, ``failedCells``, ``idle()``).
"""

from __future__ import annotations

from html import escape
from pathlib import Path

#: The page's script (``view.js`` beside this module, shipped as package data).
SCRIPT = (Path(__file__).parent / "view.js").read_text(encoding="utf-8")

STYLE = """
body { font-family: sans-serif; margin: 0.5em; }
#main { display: flex; flex-wrap: wrap; gap: 0.5em; }
#linkopt-scene { width: 62vw; min-width: 420px; height: 78vh; }
#side { flex: 1; min-width: 320px; }
#linkopt-map, #linkopt-clearance { width: 100%; height: 38vh; }
#status { margin: 0.4em 0; padding: 0.3em; }
#status.failed { background: #300; color: #fff; font-weight: bold; }
#controls input[type=range] { width: 60%; }
"""


def page(plotly_js: str, data_json: str, title: str) -> str:
    """The HTML document: ``plotly_js`` and ``data_json`` inlined (``</`` escaped so
    neither can close its script element)."""
    data = data_json.replace("</", "<\\/")
    plotly_js = plotly_js.replace("</script", "<\\/script")
    return (
        "<!DOCTYPE html>\n<html><head><meta charset='utf-8'>"
        f"<title>linkopt view: {escape(title)}</title><style>{STYLE}</style>"
        f"<script>{plotly_js}</script></head><body>"
        f"<h3>linkopt view: {escape(title)}</h3>"
        "<div id='main'><div id='linkopt-scene'></div><div id='side'>"
        "<div id='controls'></div><div id='status'></div><div id='linkopt-map'></div>"
        "<div id='linkopt-clearance'></div>"
        "<p>Drag a slider, or click the map, to move the motors; drag the 3-D view "
        "to turn it, scroll to zoom.</p></div></div>"
        f"<script type='application/json' id='linkopt-data'>{data}</script>"
        f"<script>{SCRIPT}</script></body></html>\n"
    )
