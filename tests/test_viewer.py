"""The 3-D viewer (pictures/viewer.py): its data, `spar plan --html` and `spar view`, and the page in a
real browser (headless Chromium from the distribution, driven over the DevTools protocol with the
network off). scripts/setup-browser.sh installs Chromium when it is missing; where it cannot, or
where tornado (the websocket client, in the dev extra with distributed) is missing, the browser
tests skip and say why."""
from __future__ import annotations

import asyncio
import base64
import colorsys
import io
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from spar_py.kb import load_problem
from spar_py.pictures.scene import initial_poses
from spar_py.pictures.viewer import MAX_WAYPOINTS, render_html, viewer_data
from spar_py.planning.planner import Outcome, Plan

from paths import ROOT, SPAR

PAPER = ROOT / "kb/problems/peg_in_block.yaml"
UR5E = ROOT / "kb/problems/ur5e_peg_in_block.yaml"
SETUP = ROOT / "scripts/setup-browser.sh"
#: The flags the page is opened with: headless, no sandbox (root in a container), software GL,
#: and every network request refused (a proxy on the discard port, names resolving nowhere).
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--proxy-server=127.0.0.1:9",
                  "--host-resolver-rules=MAP * ~NOTFOUND", "--window-size=1280,800", "--hide-scrollbars",
                  "--mute-audio")
PAGE_TIMEOUT_S = 60.0


def _typed(doc: dict) -> Plan:
    """The typed Plan of a plan JSON document, or of a test's partial one (the pictures take a Plan and
    read its problem, outcome, partial plan and instance)."""
    return Plan(problem=doc.get("problem", ""), outcome=Outcome(doc["outcome"]), partial=doc.get("partial"),
                instance=doc.get("instance"))


def spar(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*SPAR, *map(str, args)], capture_output=True, text=True, cwd=ROOT, timeout=timeout,
                          env={**os.environ, "PYTHONPATH": str(ROOT / "src")})


# =========================================================================== without a browser


@pytest.fixture(scope="module")
def paper_plan(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:
    """The paper's cell planned by `spar plan -o --html`: (JSON, page, plan document)."""
    d = tmp_path_factory.mktemp("paper")
    js, page = d / "plan.json", d / "plan.html"
    r = spar("plan", PAPER, "-o", js, "--html", page)
    assert r.returncode == 0, r.stderr
    assert f"wrote the viewer to {page} (4 steps, 2 parts)" in r.stderr
    return js, page, json.loads(js.read_text())


@pytest.fixture(scope="module")
def ur5e_plan(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:
    """The UR5e cell planned with its motions, and its page written by `spar view`."""
    d = tmp_path_factory.mktemp("ur5e")
    js, page = d / "plan.json", d / "viewer.html"
    r = spar("plan", UR5E, "--motion", "-o", js)
    assert r.returncode == 0, r.stderr
    r = spar("view", js, "-o", page)
    assert r.returncode == 0, r.stderr
    return js, page, json.loads(js.read_text())


def test_plan_json_names_its_problem_file(paper_plan):
    _, _, doc = paper_plan
    assert Path(doc["problem_file"]) == PAPER


def test_viewer_data_arm_from_robot_frames(paper_plan):
    """The page's arm frames are robot.frames at each step's joints; every part in every state."""
    _, _, doc = paper_plan
    cell = load_problem(PAPER)
    data = viewer_data(cell, _typed(doc))
    steps = doc["instance"]["steps"]
    assert len(data["states"]) == len(steps) + 1 and len(data["steps"]) == len(steps)
    for st, step in zip(data["states"][1:], steps):
        F = cell.robot.frames(np.radians(step["joints_deg"]))
        assert np.allclose(np.array(st["frames"]).reshape(8, 4, 4), F, atol=1e-4)
        assert set(st["parts"]) == set(initial_poses(cell))
    assert data["unit"] == "in" and [p["key"] for p in data["parts"]] == list(initial_poses(cell))
    [tol] = data["steps"][-1]["tolerances"]  # the assemble step: its one check's tolerance at the mouth
    assert tol["hole"] == "block" and tol["satisfied"] and tol["bound"] < tol["tolerance"] == pytest.approx(0.4)
    assert data["partial"]["ordering"] == doc["partial"]["ordering"]


def test_viewer_motions_sampled_and_timed(ur5e_plan):
    _, _, doc = ur5e_plan
    cell = load_problem(UR5E)
    data = viewer_data(cell, _typed(doc))
    for step, src in zip(data["steps"], doc["instance"]["steps"]):
        kinds = [m["kind"] for m in step["motion"]]
        assert kinds == ["path", "approach", "retreat"]
        for m in step["motion"]:
            assert len(m["t"]) == len(m["frames"]) <= MAX_WAYPOINTS and m["waypoints"] == len(src[m["kind"]])
            assert m["t"][0] == 0 and all(b >= a for a, b in zip(m["t"], m["t"][1:]))
        assert sum(m["t"][-1] for m in step["motion"]) == pytest.approx(src["duration_s"], rel=1e-3)
    assert data["home_motion"] is not None


def test_page_is_self_contained(paper_plan):
    _, page, _ = paper_plan
    text = page.read_text()
    assert "<script src" not in text and "import(" in text and "three.js authors" not in text  # licence in vendor/
    assert "default-src 'none'" in text  # the page's policy forbids any fetch but blob: modules


def test_view_bad_inputs(tmp_path, paper_plan):
    js, _, doc = paper_plan
    (tmp_path / "x.json").write_text('{"a": 1}')
    (tmp_path / "y.json").write_text("not json")
    no = dict(doc, outcome="no_plan")
    (tmp_path / "n.json").write_text(json.dumps(no))
    cases = [
        ((tmp_path / "missing.json",), "missing.json: no such file (expected a plan JSON"),
        ((tmp_path / "x.json",), "x.json: expected a plan JSON written by spar plan -o"),
        ((tmp_path / "y.json",), "y.json: expected a plan JSON (spar plan -o), not JSON"),
        ((tmp_path / "n.json",), "n.json: expected a plan to view, but its outcome is 'no_plan'"),
        ((js, "-o", js / "x.html"), "-o: expected a path in a directory"),
        ((js, "--problem", ROOT / "kb/problems/two_pegs.yaml", "-o", tmp_path / "o.html"),
         "expected the problem 'peg_in_block'"),
    ]
    for args, message in cases:
        r = spar("view", *args)
        assert r.returncode == 2 and message in r.stderr and len(r.stderr.splitlines()) == 1, (args, r.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["n.json", "x.json", "y.json"]  # nothing half-written


def test_plan_html_unwritable_before_planning(tmp_path):
    (tmp_path / "f").write_text("")
    r = spar("plan", PAPER, "--html", tmp_path / "f" / "x.html")
    assert r.returncode == 2 and "--html: expected a path in a directory" in r.stderr


def test_render_html_escapes_script_end(paper_plan):
    _, _, doc = paper_plan
    cell = load_problem(PAPER)
    text = render_html(cell, _typed(dict(doc, problem="</script><b>x")))
    assert "</script><b>x" not in text


# =========================================================================== in a browser


@pytest.fixture(scope="session")
def chromium() -> str:
    """The Chromium executable (scripts/setup-browser.sh installs it when missing), else skip."""
    pytest.importorskip("tornado.websocket", reason="tornado (the dev extra's websocket client) is not installed")
    try:
        r = subprocess.run(["sh", str(SETUP)], capture_output=True, text=True, timeout=1200)
    except (OSError, subprocess.TimeoutExpired) as e:
        pytest.skip(f"headless Chromium could not be set up: {e}")
    if r.returncode != 0 or not r.stdout.strip():
        pytest.skip(f"headless Chromium could not be installed: {r.stderr.strip() or 'setup-browser.sh failed'}")
    return r.stdout.strip().splitlines()[-1]


class Browser:
    """A headless Chromium with its DevTools endpoint, in a private profile; closed by :meth:`close`."""

    def __init__(self, exe: str, profile: Path) -> None:
        self.profile = profile
        self.proc = subprocess.Popen([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--remote-debugging-port=0",
                                      "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True)
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + 30
        while not port_file.exists() or len(port_file.read_text().split()) < 2:
            if time.monotonic() > deadline or self.proc.poll() is not None:
                self.close()
                raise RuntimeError("Chromium did not open its DevTools port")
            time.sleep(0.05)
        port, path = port_file.read_text().split()[:2]
        self.ws_url = f"ws://127.0.0.1:{port}{path}"

    def close(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()


class Session:
    """One page over the DevTools protocol (flattened target session): commands and the events seen."""

    def __init__(self, conn) -> None:
        self.conn, self.next_id, self.events, self.session = conn, 0, [], None

    async def send(self, method: str, params: dict | None = None, top: bool = False) -> dict:
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if self.session and not top:
            msg["sessionId"] = self.session
        await self.conn.write_message(json.dumps(msg))
        while True:
            raw = await asyncio.wait_for(self.conn.read_message(), PAGE_TIMEOUT_S)
            if raw is None:
                raise RuntimeError("DevTools connection closed")
            m = json.loads(raw)
            if m.get("id") == self.next_id:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})
            if "method" in m:
                self.events.append(m)

    async def evaluate(self, expr: str, await_promise: bool = False):
        r = await self.send("Runtime.evaluate", {"expression": expr, "returnByValue": True,
                                                 "awaitPromise": await_promise})
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expr}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def errors(self) -> list[str]:
        """JavaScript errors seen: exceptions, console.error, error log entries (not the browser's own)."""
        out = []
        for e in self.events:
            m, p = e["method"], e.get("params", {})
            if m == "Runtime.exceptionThrown":
                out.append(json.dumps(p["exceptionDetails"])[:300])
            elif m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                out.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
            elif m == "Log.entryAdded" and p["entry"].get("level") == "error":
                out.append(p["entry"].get("text", ""))
        return out

    def requests(self) -> list[str]:
        """URLs the page asked for other than its own file and the blob:/data: URLs it makes."""
        return [e["params"]["request"]["url"] for e in self.events if e["method"] == "Network.requestWillBeSent"
                and not e["params"]["request"]["url"].startswith(("file:", "blob:", "data:"))]


async def _visit(ws_url: str, url: str, point_expr: str) -> dict:
    """Open ``url``, wait until the page is drawn (data-steps on <body>), then read its body's data,
    the projection of the world point ``point_expr`` evaluates to, a screenshot, errors and requests."""
    from tornado.websocket import websocket_connect

    conn = await websocket_connect(ws_url, max_message_size=256 * 2**20)
    try:
        s = Session(conn)
        target = (await s.send("Target.createTarget", {"url": "about:blank"}))["targetId"]
        s.session = (await s.send("Target.attachToTarget", {"targetId": target, "flatten": True}))["sessionId"]
        for domain in ("Runtime", "Log", "Network", "Page"):
            await s.send(f"{domain}.enable")
        await s.send("Emulation.setDeviceMetricsOverride", {"width": 1280, "height": 800, "deviceScaleFactor": 1,
                                                             "mobile": False})
        await s.send("Page.navigate", {"url": url})
        deadline = time.monotonic() + PAGE_TIMEOUT_S
        body: dict = {}
        while time.monotonic() < deadline:
            body = json.loads(await s.evaluate("JSON.stringify(document.body ? {...document.body.dataset} : {})")
                              or "{}")
            if "steps" in body or "error" in body:
                break
            await asyncio.sleep(0.1)
        await s.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", True)
        point = await s.evaluate(point_expr) if "steps" in body else None
        proj = await s.evaluate(f"JSON.stringify(window.sparProject({json.dumps(point)}))") if point else None
        boxes = await s.evaluate("JSON.stringify(window.sparBoxes ? window.sparBoxes() : null)")
        shot = (await s.send("Page.captureScreenshot", {"format": "png"}))["data"]
        await s.evaluate("1")  # any late console message is in by now
        return {"body": body, "point": point, "proj": json.loads(proj) if proj else None,
                "boxes": json.loads(boxes) if boxes else None,
                "png": base64.b64decode(shot), "errors": s.errors(), "requests": s.requests()}
    finally:
        conn.close()


def _open(chromium: str, tmp_path: Path, page: Path, step: int, point_expr: str) -> dict:
    browser = Browser(chromium, tmp_path / "profile")
    try:
        return asyncio.run(_visit(browser.ws_url, f"{page.as_uri()}#step={step}", point_expr))
    finally:
        browser.close()
        shutil.rmtree(tmp_path / "profile", ignore_errors=True)


def _part_pixels(png: bytes, centre: list[float], colours: list[str], radius: int = 30) -> int:
    """Pixels within ``radius`` px of ``centre`` of one of the parts' colours (their hue, shaded)."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), float) / 255
    h, w, _ = img.shape
    cx, cy = int(round(centre[0])), int(round(centre[1]))
    patch = img[max(0, cy - radius):min(h, cy + radius), max(0, cx - radius):min(w, cx + radius)].reshape(-1, 3)
    n = 0
    for c in colours:
        hue, sat, _ = colorsys.rgb_to_hsv(*(int(c[i:i + 2], 16) / 255 for i in (1, 3, 5)))
        hsv = np.array([colorsys.rgb_to_hsv(*p) for p in patch])
        dh = np.minimum(abs(hsv[:, 0] - hue), 1 - abs(hsv[:, 0] - hue))
        n += int(np.count_nonzero((dh < 0.035) & (hsv[:, 1] > 0.6 * sat) & (hsv[:, 2] > 0.15)))
    return n


def _check_page(result: dict, doc: dict, cell_path: Path) -> None:
    cell = load_problem(cell_path)
    assert result["errors"] == [], result["errors"]
    assert result["requests"] == [], result["requests"]
    assert result["body"].get("steps") == str(len(doc["instance"]["steps"])), result["body"]
    assert result["body"].get("parts") == str(len(initial_poses(cell))), result["body"]
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(result["png"])).convert("RGB"))
    assert img.shape[:2] == (800, 1280)
    view = img[:, :900]
    assert view.std() > 10 and len(np.unique(view.reshape(-1, 3), axis=0)) > 200  # not blank
    x, y = result["proj"]
    assert 0 <= x < 900 and 0 <= y < 800, result["proj"]  # the hole is in the 3-D view
    colours = [p["colour"] for p in viewer_data(cell, _typed(doc))["parts"]]
    assert _part_pixels(result["png"], [x, y], colours) >= 300  # of the 3600 pixels round the hole


def _check_boxes(boxes: list[dict] | None, step: dict, cell_path: Path) -> None:
    """The page draws each part's uncertainty box from the step's propagated bounds: the part's
    world box (its mesh at its pose) moved by the bounds of its origin (a part that cannot turn
    about z here, so no widening for a turn; the page rounds the bounds outwards to 5 decimals)."""
    from spar_py.pictures.scene import part_model
    from spar_py.pictures.viewer import part_triangles

    cell = load_problem(cell_path)
    assert boxes is not None and {b["part"] for b in boxes} == set(step["position_bounds"]), boxes
    for b in boxes:
        bounds = step["position_bounds"][b["part"]]
        assert bounds["dtheta_deg"] == [0.0, 0.0]
        T = np.asarray(step["poses"][b["part"]], float)
        pts = part_triangles(cell.objects[part_model(b["part"])], cell.unit).reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        lo = pts.min(axis=0) + [bounds[k][0] for k in ("dx", "dy", "dz")]
        hi = pts.max(axis=0) + [bounds[k][1] for k in ("dx", "dy", "dz")]
        assert np.allclose(b["min"], lo, atol=2e-5) and np.allclose(b["max"], hi, atol=2e-5), (b, lo, hi)


def _assemble_step(doc: dict) -> int:
    return 1 + next(k for k, s in enumerate(doc["instance"]["steps"]) if s["name"] == "assemble")


def test_browser_paper_cell(chromium, tmp_path, paper_plan):
    """The paper's cell's page, at its assemble step: drawn, no error, the parts at the hole."""
    _, page, doc = paper_plan
    k = _assemble_step(doc)
    t0 = time.monotonic()
    result = _open(chromium, tmp_path, page, k, f"window.sparData.steps[{k - 1}].tolerances[0].centre")
    assert result["body"].get("state") == str(k)
    _check_page(result, doc, PAPER)
    assert time.monotonic() - t0 < 60
    _check_boxes(result["boxes"], doc["instance"]["steps"][k - 1], PAPER)
    if os.environ.get("SPAR_VIEWER_SHOT"):  # docs/viewer.png is this screenshot
        Path(os.environ["SPAR_VIEWER_SHOT"]).write_bytes(result["png"])


def test_browser_ur5e_with_motions(chromium, tmp_path, ur5e_plan):
    """A UR5e cell with its motions (spar view's page), at its assemble step."""
    _, page, doc = ur5e_plan
    assert doc["instance"]["motion"] is not None
    k = _assemble_step(doc)
    result = _open(chromium, tmp_path, page, k, f"window.sparData.steps[{k - 1}].tolerances[0].centre")
    _check_page(result, doc, UR5E)


def test_browser_plays_a_motion(chromium, tmp_path, ur5e_plan):
    """Playing a step's motion shows the world before the step, then, after its duration, the step (no error)."""
    _, page, doc = ur5e_plan
    expr = "document.getElementById('play').click()"
    browser = Browser(chromium, tmp_path / "profile")

    async def run() -> tuple[list, list, str]:
        from tornado.websocket import websocket_connect

        conn = await websocket_connect(browser.ws_url, max_message_size=256 * 2**20)
        try:
            s = Session(conn)
            target = (await s.send("Target.createTarget", {"url": "about:blank"}))["targetId"]
            s.session = (await s.send("Target.attachToTarget", {"targetId": target, "flatten": True}))["sessionId"]
            await s.send("Runtime.enable")
            await s.send("Page.navigate", {"url": f"{page.as_uri()}#step=1"})
            for _ in range(600):
                if await s.evaluate("document.body && document.body.dataset.steps || ''"):
                    break
                await asyncio.sleep(0.1)
            await s.evaluate(expr)
            await asyncio.sleep(0.3)
            mid = await s.evaluate("[document.body.dataset.state, document.body.dataset.playing]")
            await asyncio.sleep(float(doc["instance"]["steps"][0]["duration_s"]) + 1.0)
            end = await s.evaluate("[document.body.dataset.state, document.body.dataset.playing]")
            return s.errors(), mid, end
        finally:
            conn.close()

    try:
        errors, mid, end = asyncio.run(run())
    finally:
        browser.close()
    assert errors == [] and mid == ["0", "1"] and end == ["1", None]


def test_part_without_shape_drawn_as_marker():
    from spar_py.core.model import ObjectModel
    from spar_py.pictures.viewer import MARKER_MM, part_triangles

    tris = part_triangles(ObjectModel("bare", (), {}, {}), "in")
    assert tris.shape == (12, 3, 3) and np.ptp(tris.reshape(-1, 3), axis=0) == pytest.approx([MARKER_MM / 25.4] * 3)
