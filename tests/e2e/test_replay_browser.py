"""The replay page in a real browser: headless Chromium driven by Selenium (chromedriver).

Marked `browser`: in the default suite, skipped where selenium, chromium or chromedriver is
not installed (.ci/run installs them: `apt-get install chromium chromium-driver`, the `dev`
extra's selenium)."""

import re
import shutil
import time

import pytest
from replaykit import DESIGNS

from swarmcode_torch.app.replay_page import page_data, write_page
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.sim.scenario import load_scenario

pytestmark = [pytest.mark.browser, pytest.mark.subprocess]

webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")

CHROMIUM = next(
    (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None
)
DRIVER = shutil.which("chromedriver")
if CHROMIUM is None or DRIVER is None:
    pytest.skip("chromium and chromedriver are not installed", allow_module_level=True)


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    data = page_data(
        DESIGNS,
        load_scenario("two-niche"),
        SwarmCoDeConfig(scenario="two-niche"),
        seed=1,
        title="browser test",
    )
    return write_page(data, tmp_path_factory.mktemp("page") / "team.html"), data


def _driver():
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    for a in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1280,800",
    ):
        opts.add_argument(a)
    opts.binary_location = CHROMIUM
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        drv = webdriver.Chrome(service=Service(DRIVER), options=opts)
    except Exception as e:  # a browser that does not start is not a failure of the page
        pytest.skip(f"headless chromium does not start here: {e}")
    return drv


def _open(drv, path):
    drv.get(path.resolve().as_uri())
    _wait(
        drv,
        "return document.body.dataset.ready === '1' || !document.getElementById('error').hidden",
    )


@pytest.fixture(scope="module")
def browser(page):
    drv = _driver()
    _open(drv, page[0])
    yield drv
    drv.quit()


def _wait(drv, script, timeout=20.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if drv.execute_script(script):
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for: {script}")


def _text(drv, testid):
    return drv.find_element("css selector", f'[data-testid="{testid}"]').text


def _scrub(drv, t):
    el = drv.find_element("id", "scrub")
    drv.execute_script(
        "arguments[0].value = arguments[1];"
        "arguments[0].dispatchEvent(new Event('input', {bubbles: true}));",
        el,
        t,
    )


def test_loads_without_console_errors(browser):
    assert browser.find_element("id", "error").get_attribute("hidden") is not None
    assert browser.execute_script("return document.body.dataset.ready") == "1"
    logs = [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert logs == []
    assert browser.find_element("id", "title").text == "browser test"


def test_scrubbing_to_the_last_tick_shows_the_recorded_counts(browser, page):
    data = page[1]
    _scrub(browser, data["ticks"])
    assert browser.find_element("id", "tick").text == f"tick {data['ticks']} / {data['ticks']}"
    for name in ("focal", "baseline"):
        m = data["panels"][name]["metrics"]
        assert (
            int(_text(browser, f"delivered-{name}"))
            == m["delivered_individual"] + m["delivered_collab"]
        )
        assert int(_text(browser, f"picked-{name}")) == m["picked_individual"] + m["picked_collab"]
        assert float(_text(browser, f"energy-{name}")) == pytest.approx(m["energy_used"], abs=0.006)
    assert int(_text(browser, "delivered-focal")) > 0


def test_clicking_a_robot_shows_its_design_and_tree(browser, page):
    from selenium.webdriver.common.action_chains import ActionChains

    data = page[1]
    _scrub(browser, 40)
    canvas = browser.find_element("id", "canvas-baseline")
    # all of the canvas in view: the pointer's offset is from the centre of its visible part
    browser.execute_script("arguments[0].scrollIntoView({block: 'center'})", canvas)
    robot = 15  # a partner slot: design 1 (suction)
    pos = browser.execute_script("return window.replay.screenPos('baseline', arguments[0])", robot)
    size = canvas.size
    ActionChains(browser).move_to_element_with_offset(
        canvas, pos["cx"] - size["width"] / 2, pos["cy"] - size["height"] / 2
    ).click().perform()
    tip = browser.find_element("id", "tooltip")  # the pointer rests on it: hover
    assert tip.is_displayed() and tip.text.startswith(f"robot {robot}: ")
    title = _text(browser, "robot-title")
    d = data["designs"][data["panels"]["baseline"]["robots"]["design"][robot]]
    assert f"Robot {robot} of the baseline team" in title and f"sp {d['species']}" in title
    table = _text(browser, "robot-design")
    assert d["effector"] in table and f"chassis {d['chassis_tier']}" in table
    assert f"${d['cost']:.0f}" in table
    tree = _text(browser, "tree")
    assert tree.splitlines()[0].startswith("SEQ (root)")
    acting = browser.find_elements("css selector", "pre.tree .acting")
    assert len(acting) <= 1 and "tick 40" in _text(browser, "acting")
    if acting:  # the highlighted line names the acting node
        assert acting[0].text.split()[0] in _text(browser, "acting")


def test_focal_and_baseline_advance_together(browser, page):
    data = page[1]
    _scrub(browser, 0)
    shots0 = {
        n: browser.execute_script(f"return document.getElementById('canvas-{n}').toDataURL()")
        for n in ("focal", "baseline")
    }
    from selenium.webdriver.support.select import Select

    Select(browser.find_element("id", "speed")).select_by_value("8")
    browser.find_element("id", "play").click()
    _wait(browser, "return window.replay.tick >= 30")
    browser.find_element("id", "play").click()  # pause
    t = browser.execute_script("return window.replay.tick")
    assert 30 <= t <= data["ticks"]
    assert browser.find_element("id", "tick").text == f"tick {t} / {data['ticks']}"
    for n in ("focal", "baseline"):
        shot = browser.execute_script(f"return document.getElementById('canvas-{n}').toDataURL()")
        assert shot != shots0[n], n  # both arenas moved on
        counts = browser.execute_script(f"return window.replay.data.panels.{n}.counts[{t}]")
        assert int(_text(browser, f"delivered-{n}")) == counts["di"] + counts["dc"]
    # one step on moves both
    browser.find_element("id", "fwd").click()
    assert browser.execute_script("return window.replay.tick") == t + 1
    assert browser.find_element("id", "tick").text == f"tick {t + 1} / {data['ticks']}"


def test_the_page_shows_deliveries_per_robot_and_design_and_the_divergence_tick(browser, page):
    data = page[1]
    part = data["divergence"]
    assert part is not None and 0 < part["tick"] < data["ticks"]
    assert int(_text(browser, "divergence-tick")) == part["tick"]
    assert f"robot {part['robot']} " in _text(browser, "divergence")
    button = browser.find_element("id", "goto-divergence")
    browser.execute_script("arguments[0].scrollIntoView({block: 'center'})", button)
    button.click()
    assert browser.execute_script("return window.replay.tick") == part["tick"]
    assert browser.find_element("id", "tick").text == f"tick {part['tick']} / {data['ticks']}"
    for t in (part["tick"], data["ticks"]):  # the tables count what happened up to the tick
        _scrub(browser, t)
        assert int(_text(browser, "credits-tick")) == t
        for name in ("focal", "baseline"):
            p = data["panels"][name]
            c = [p["credits"][i : i + 4] for i in range(0, len(p["credits"]), 4)]
            for r, d in enumerate(p["robots"]["design"]):
                want = sum(tk <= t and rr == r and k < 2 for tk, rr, _, k in c)
                if d >= 0:
                    cell = _text(browser, f"deliv-{name}-r{r}").split()[0]
                    assert int(cell) == want, (name, r, t)
            for d in set(p["robots"]["design"]) - {-1}:
                want = sum(
                    tk <= t and p["robots"]["design"][rr] == d and k >= 2 for tk, rr, _, k in c
                )
                assert int(_text(browser, f"picked-{name}-d{d}").split()[0]) == want
    # at the end, the individual deliveries per robot add up to the team's
    for name in ("focal", "baseline"):
        p = data["panels"][name]
        total = 0
        for r, d in enumerate(p["robots"]["design"]):
            if d >= 0:
                m = re.fullmatch(
                    r"(\d+)(?: \((\d+) collab\))?", _text(browser, f"deliv-{name}-r{r}")
                )
                total += int(m[1]) - int(m[2] or 0)
        assert total == p["metrics"]["delivered_individual"]
    # a clicked robot lists what it delivered
    p = data["panels"]["focal"]
    r = p["credits"][1] if p["credits"] else 0
    browser.execute_script("window.replay.select('focal', arguments[0])", r)
    text = _text(browser, "robot-credits")
    if p["credits"]:
        t0, _, q, k = p["credits"][:4]
        assert f"#{q} at tick {t0}" in text


def test_the_mean_marginal_over_several_environments_is_shown(tmp_path):
    data = page_data(
        DESIGNS,
        load_scenario("two-niche"),
        SwarmCoDeConfig(scenario="two-niche"),
        seed=1,
        ticks=40,
        seeds=3,
    )
    drv = _driver()
    try:
        _open(drv, write_page(data, tmp_path / "team.html"))
        sm = data["seed_marginals"]
        assert float(_text(drv, "mean-marginal")) == pytest.approx(sm["mean"], abs=0.06)
        assert "Over 3 environments (seeds 1–3)" in drv.find_element("id", "summary").text
    finally:
        drv.quit()


# ------------------------------------------------------------------ hostile run data
PLANTED = "<img src=x onerror=window.__planted=1><svg onload=window.__planted=2>"


def test_a_page_of_hostile_run_data_runs_no_planted_script(tmp_path):
    """Text planted in every run-data field the page shows (designs' species and effector, the
    record's generation, the title, a class label) reaches the page as text, and nothing runs."""
    designs = [dict(d, species=PLANTED) for d in DESIGNS]
    data = page_data(
        designs,
        load_scenario("two-niche"),
        SwarmCoDeConfig(scenario="two-niche"),
        seed=1,
        title=PLANTED,
        record={"generation": PLANTED, "fitness": 1.0},
    )
    data["designs"][0]["effector"] = PLANTED
    data["classes"][0] = PLANTED
    data["p_marginal"] = PLANTED
    path = write_page(data, tmp_path / "team.html")
    drv = _driver()
    try:
        _open(drv, path)
        assert drv.execute_script("return document.body.dataset.ready") == "1"
        drv.find_element("id", "play").click()
        drv.find_element("id", "play").click()
        drv.execute_script(
            "const c = document.getElementById('canvas-focal'), r = c.getBoundingClientRect();"
            "c.dispatchEvent(new MouseEvent('click', {clientX: r.left + r.width / 2,"
            " clientY: r.top + r.height / 2, bubbles: true}));"
        )
        time.sleep(0.3)
        assert drv.execute_script("return window.__planted === undefined")
        # the planted markup is shown as text, not made into elements
        assert (
            drv.execute_script(
                "return document.querySelectorAll('#summary img, #legend img, #credits img,"
                " #divergence img').length"
            )
            == 0
        )
        assert PLANTED in drv.find_element("id", "summary").text
        assert PLANTED in drv.find_element("id", "legend").text
        assert PLANTED in drv.find_element("id", "credits").text
    finally:
        drv.quit()


def test_the_pages_policy_forbids_inline_handlers_even_where_markup_gets_in(browser):
    """Defence in depth: were some value to reach innerHTML unescaped, the page's
    Content-Security-Policy refuses its inline event handler."""
    browser.execute_script(
        "document.getElementById('summary').insertAdjacentHTML('beforeend',"
        " '<img src=x onerror=\"window.__inline=1\">');"
    )
    time.sleep(0.3)
    assert browser.execute_script("return window.__inline === undefined")
    assert browser.execute_script("return document.querySelectorAll('#summary img').length") == 1
