"""The live console in a real browser: headless Chromium (Debian's chromium and chromium-driver,
driven by Selenium) clicks, drags and presses STOP on the page, judged at the pins by the
simulated board's and the emulated Uno's trace; the plots, the failsafe on the page's
liveness, the two pages and the token (docs/console.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from protoduino import Board
from protoduino.console import ConsoleServer, LiveBoard, PinSpec
from protoduino.console.server import COOKIE
from protoduino.simboard import SimBoard
from simfixtures import pin_values, wait_for_pin, wait_until

webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.common.keys import Keys  # noqa: E402
from selenium.webdriver.support.select import Select  # noqa: E402

CHROMIUM = shutil.which("chromium")
CHROMEDRIVER = shutil.which("chromedriver")

#: The failsafe timeout of these tests' boards: the page's heartbeat comes every T/4.
T = 1.0
SAFE_90_US = 1472  # 90 degrees on the default 544..2400 us
PINS = (
    PinSpec(9, "servo", safe=90, name="pan"),
    PinSpec(13, "digital", safe=0, name="led"),
    PinSpec(3, "pwm", safe=0, name="motor"),
    PinSpec(14, "analog", name="battery"),
    PinSpec(7, "input", pull_up=True, name="bumper"),
    PinSpec(2, "counter", name="encoder"),
)


@dataclass
class Console:
    sim: SimBoard
    board: Board
    live: LiveBoard
    server: ConsoleServer


@pytest.fixture
def console(sim_board: SimBoard) -> Iterator[Console]:
    """The console on the simulated board (either backend), serving PINS on a free port."""
    with Board.open(sim_board.port, liveness="heartbeat", failsafe_timeout=T) as board:
        live = LiveBoard(board, window=10.0)
        live.configure_all(PINS)
        with ConsoleServer(live) as server:
            yield Console(sim_board, board, live, server)
        live.close()


Browser = Callable[[str], Any]


@pytest.fixture
def browser() -> Iterator[Browser]:
    """Opens a page in a new headless Chromium each call; every one is quit at the end."""
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("chromium or chromedriver is not installed (Debian: chromium chromium-driver)")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opened: list[Any] = []
    profiles: list[str] = []

    def open_page(url: str) -> Any:
        options = Options()
        options.binary_location = CHROMIUM
        profile = tempfile.mkdtemp(prefix="protoduino-chromium-")
        profiles.append(profile)
        for flag in (
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-dev-shm-usage",
            "--window-size=1500,1000",
            f"--user-data-dir={profile}",
        ):
            options.add_argument(flag)
        driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
        opened.append(driver)
        driver.get(url)
        return driver

    try:
        yield open_page
    finally:
        for driver in opened:
            with contextlib.suppress(Exception):  # a page the test closed itself
                driver.quit()
        for profile in profiles:
            shutil.rmtree(profile, ignore_errors=True)


def text_of(page: Any, element_id: str) -> str:
    return str(page.find_element(By.ID, element_id).text)


def until(predicate: Callable[[], bool], what: str, timeout: float = 30.0) -> None:
    """Until ``predicate`` holds; the timeout only bounds a failure."""
    assert wait_until(predicate, timeout), f"timed out waiting for {what}"


def driving(page: Any) -> None:
    """Until the page drives, and a failsafe that fired while no page drove (the fixture's
    board waits for a page with a failsafe timeout of T) is cleared by its heartbeat: a
    command the page sends before that is refused (STATUS_FAILSAFE_EXPIRED), as it should."""
    until(lambda: text_of(page, "role") == "driving", "the page to drive")
    until(lambda: "ACTIVE" not in text_of(page, "failsafe"), "the page's heartbeat to re-arm")


def now_at(value: int) -> Callable[[list[int]], bool]:
    return lambda values: values[-1:] == [value]


def test_the_page_drives_every_output_kind_and_stop_makes_them_safe(
    console: Console, browser: Browser, tmp_path: Path
) -> None:
    """A toggle clicked, a servo and a PWM slider dragged, STOP pressed: at the pins."""
    sim = console.sim
    page = browser(console.server.url)
    driving(page)

    page.find_element(By.ID, "toggle-13").click()
    wait_for_pin(sim, 13, now_at(1))
    until(lambda: text_of(page, "readback-13") == "on", "the readback of pin 13")
    until(lambda: "Outputs live" in text_of(page, "failsafe"), "the outputs live")

    servo = page.find_element(By.ID, "servo-9")
    ActionChains(page).drag_and_drop_by_offset(servo, -60, 0).perform()
    moved = wait_for_pin(sim, 9, lambda v: bool(v) and v[-1] < SAFE_90_US - 100)
    until(
        lambda: text_of(page, "readback-9").startswith(f"{moved[-1]}"),
        "the readback of pin 9",
    )

    motor = page.find_element(By.ID, "pwm-3")
    ActionChains(page).drag_and_drop_by_offset(motor, 50, 0).perform()
    wait_for_pin(sim, 3, lambda v: bool(v) and v[-1] > 128)

    page.save_screenshot(str(tmp_path / "console.png"))
    page.find_element(By.ID, "stop").click()
    wait_for_pin(sim, 9, now_at(SAFE_90_US))
    wait_for_pin(sim, 13, now_at(0))
    wait_for_pin(sim, 3, now_at(0))
    until(lambda: "SAFE after stop" in text_of(page, "failsafe"), "the page's STOP state")


def test_the_plots_show_every_input_kind_the_control_socket_moves(
    console: Console, browser: Browser
) -> None:
    """An analog input, a digital input and a counter, moved by the simulated board's
    control socket: each value on the page and in its plot, in order, within the window."""
    sim = console.sim
    page = browser(console.server.url)
    driving(page)

    def plot(pin: int) -> list[list[float]]:
        data: list[list[float]] = page.execute_script(
            f"return protoduinoConsole.plots[{pin}].data;"
        )
        return data

    def shows(pin: int, value: int) -> Callable[[], bool]:
        return lambda: text_of(page, f"value-{pin}") == str(value) and value in plot(pin)[1]

    for counts in (700, 300):
        sim.set_analog(14, counts)
        until(shows(14, counts), f"A0 at {counts} on the page and in its plot")
    xs, ys = plot(14)
    assert ys.index(700) < len(ys) - 1 - ys[::-1].index(300), ys
    assert all(-10.0 <= x <= 0 for x in xs), xs
    assert "s old" in text_of(page, "age-14")

    until(shows(7, 1), "the bumper released (pull-up)")
    sim.set_level(7, 0)
    until(shows(7, 0), "the bumper pressed")
    assert plot(7)[1][-2:] == [1, 0] or plot(7)[1][-3:-1] == [1, 0], plot(7)

    sim.pulses(2, 25, 500)
    until(shows(2, 25), "25 edges counted")
    assert 0 in plot(2)[1], plot(2)


def test_a_pin_configured_on_the_page_is_driven(console: Console, browser: Browser) -> None:
    sim = console.sim
    page = browser(console.server.url)
    driving(page)
    Select(page.find_element(By.ID, "cfg-pin")).select_by_value("12")
    Select(page.find_element(By.ID, "cfg-mode")).select_by_value("digital")
    page.find_element(By.ID, "cfg-safe").send_keys("0")
    page.find_element(By.ID, "cfg-name").send_keys("horn")
    page.find_element(By.CSS_SELECTOR, "#configure button").click()
    until(lambda: bool(page.find_elements(By.ID, "toggle-12")), "pin 12 on the page")
    assert "horn" in text_of(page, "out-12")
    page.find_element(By.ID, "toggle-12").click()
    wait_for_pin(sim, 12, now_at(1))
    # A mode the pin cannot do is refused, with the board's reason on the page.
    Select(page.find_element(By.ID, "cfg-pin")).select_by_value("4")
    Select(page.find_element(By.ID, "cfg-mode")).select_by_value("pwm")
    page.find_element(By.CSS_SELECTOR, "#configure button").click()
    until(lambda: "pin 4 cannot be a pwm pin" in text_of(page, "error"), "the refusal of pin 4")
    assert not page.find_elements(By.ID, "pwm-4")


def test_the_page_goes_on_through_a_reboot_and_says_so(console: Console, browser: Browser) -> None:
    sim = console.sim
    page = browser(console.server.url)
    driving(page)
    page.find_element(By.ID, "toggle-13").click()
    wait_for_pin(sim, 13, now_at(1))
    sim.reboot()  # a power cycle: the board restores every output at its safe value
    wait_for_pin(sim, 13, now_at(0))
    until(lambda: "rebooted" in text_of(page, "events"), "the reboot on the page")
    until(lambda: "restored" in text_of(page, "events"), "the restore on the page")
    until(lambda: text_of(page, "toggle-13") == "OFF", "the led shown safe")
    until(lambda: "Board connected" in text_of(page, "banner"), "the link shown up")
    page.find_element(By.ID, "toggle-13").click()  # the page drives on
    wait_for_pin(sim, 13, now_at(1))


def test_closing_the_page_trips_the_failsafe_on_time(console: Console, browser: Browser) -> None:
    """While the page lives its heartbeat holds the outputs (2 T of the board's clock); once
    it is closed the device drives them safe T after its last beat."""
    sim = console.sim
    page = browser(console.server.url)
    driving(page)
    servo = page.find_element(By.ID, "servo-us-9")
    servo.click()  # focused, the page no longer shows the readback there
    servo.send_keys(Keys.CONTROL, "a")
    servo.send_keys("1000", Keys.ENTER)
    wait_for_pin(sim, 9, now_at(1000))
    commanded = [c for c in sim.trace() if c["pin"] == 9][-1]["t"]
    t = commanded
    toggle = page.find_element(By.ID, "toggle-13")
    level = 0
    while t - commanded < 2 * T:  # the led's edges date the board's clock
        toggle.click()
        level ^= 1
        wait_for_pin(sim, 13, now_at(level))
        t = [c for c in sim.trace() if c["pin"] == 13][-1]["t"]
        time.sleep(0.2)
    assert pin_values(sim.trace(), 9)[-1] == 1000, "the failsafe fired with the page alive"

    page.close()  # the tab closes: no more beats
    wait_for_pin(sim, 9, now_at(SAFE_90_US))
    changes = [c for c in sim.trace() if c["pin"] == 9]
    tripped = changes[-1]["t"]
    # The last beat came at most T/4 before the last edge, and the close follows that edge
    # by what Selenium takes to close a tab (well under a second).
    assert 0.75 * T - 0.05 <= tripped - t <= T + 1.0, (tripped, t)

    # A new page drives on through the failsafe: it says what happened, and its heartbeat
    # re-arms the device.
    page = browser(console.server.url)
    driving(page)
    until(lambda: "heartbeat_timeout" in text_of(page, "failsafe"), "the failsafe on the page")
    page.find_element(By.ID, "toggle-13").click()
    wait_for_pin(sim, 13, now_at(1))  # the failsafe left it off (safe), the toggle turns it on
    until(lambda: "Outputs live" in text_of(page, "failsafe"), "the outputs live again")


def test_a_page_that_stops_talking_trips_the_failsafe_and_is_told(
    console: Console, browser: Browser
) -> None:
    """A laptop asleep or a network gone: the WebSocket stays open, nothing comes from the
    page. Its socket still open, the device drives the outputs safe, and the page (which still
    hears the console) says so."""
    sim = console.sim
    page = browser(console.server.url)
    driving(page)
    page.find_element(By.ID, "toggle-13").click()
    wait_for_pin(sim, 13, now_at(1))
    page.execute_script("protoduinoConsole.ws.send = () => {};")  # the page falls silent
    wait_for_pin(sim, 13, now_at(0))
    until(
        lambda: "FAILSAFE ACTIVE (heartbeat_timeout)" in text_of(page, "failsafe"),
        "the failsafe on the silent page",
    )
    assert text_of(page, "role") == "driving"  # still connected: only its beats stopped


def test_two_pages_one_drives_the_other_watches(console: Console, browser: Browser) -> None:
    sim = console.sim
    first = browser(console.server.url)
    driving(first)
    second = browser(console.server.url)
    until(lambda: text_of(second, "role") == "watching", "the second page to watch")
    assert not second.find_element(By.ID, "take").is_displayed()

    second.find_element(By.ID, "toggle-13").click()
    until(lambda: "this page watches" in text_of(second, "error"), "the watcher's refusal")
    assert 1 not in pin_values(sim.trace(), 13)

    first.find_element(By.ID, "toggle-13").click()
    wait_for_pin(sim, 13, now_at(1))
    second.find_element(By.ID, "stop").click()  # STOP works from any page
    wait_for_pin(sim, 13, now_at(0))

    first.close()  # the driver goes: nobody drives until the watcher takes over
    take = second.find_element(By.ID, "take")
    until(take.is_displayed, "the watcher's Take control")
    take.click()
    driving(second)
    second.find_element(By.ID, "toggle-13").click()
    wait_for_pin(sim, 13, now_at(1))


def _status(url: str, headers: dict[str, str] | None = None) -> int:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {})) as r:
            return int(r.status)
    except urllib.error.HTTPError as error:
        return int(error.code)


def _websocket(base: str, origin: str) -> int:
    """The status of a WebSocket handshake from ``origin`` carrying the token's cookie."""
    import aiohttp

    async def connect() -> int:
        async with aiohttp.ClientSession(cookies={COOKIE: "sesame"}) as session:
            try:
                async with session.ws_connect(base + "ws", origin=origin) as ws:
                    await ws.receive_json()  # the first picture
                    return 101
            except aiohttp.WSServerHandshakeError as error:
                return error.status

    return asyncio.run(connect())


@pytest.mark.parametrize("sim_board", ["native"], indirect=True)
def test_every_request_without_the_token_is_refused(sim_board: SimBoard, browser: Browser) -> None:
    """Off loopback a token is made; without it the page, its assets and the WebSocket are
    refused (403), with it the page works; another site's page cannot open the WebSocket."""
    with Board.open(sim_board.port, liveness="heartbeat", failsafe_timeout=T) as board:
        live = LiveBoard(board)
        live.configure_all(PINS[:2])
        assert ConsoleServer(live, host="0.0.0.0").token is not None
        assert ConsoleServer(live).token is None  # 127.0.0.1: none unless asked for
        with ConsoleServer(live) as open_server:
            url = open_server.url
            assert _status(url) == 200
            # DNS rebinding: another name resolved to 127.0.0.1 is not this machine's page.
            assert _status(url, {"Host": "rebound.example"}) == 403
            assert (
                _status(url, {"Host": url.split("/")[2].replace("127.0.0.1", "localhost")}) == 200
            )
        with ConsoleServer(live, token="sesame") as server:
            base = server.url.split("?")[0]
            assert server.url == f"{base}?token=sesame"
            for path in ("", "static/console.js", "vendor/uPlot.iife.min.js", "ws"):
                assert _status(base + path) == 403, path
                assert _status(f"{base}{path}?token=wrong") == 403, path
            assert _status(base + "static/console.js?token=sesame") == 200
            page = browser(base)
            assert "needs the access token" in page.find_element(By.TAG_NAME, "body").text
            page.get(server.url)  # the printed URL: its token, then the cookie
            driving(page)
            page.find_element(By.ID, "toggle-13").click()
            wait_for_pin(sim_board, 13, now_at(1))
            # Another site's page in the same browser (its cookie sent along): refused; the
            # console's own origin with the cookie: let in.
            assert _websocket(base, "http://evil.example") == 403
            assert _websocket(base, base.rstrip("/")) == 101
        live.close()


@pytest.mark.parametrize("backend", ["native", "avr"])
def test_the_command_serves_the_example_robot_and_stops_it(backend: str, tmp_path: Path) -> None:
    """``protoduino console --sim --foxglove``: the example robot on the page, a write at the
    pin, the token asked for, the Foxglove server beside, SIGTERM -> the outputs stopped and
    exit status 0."""
    if shutil.which("avr-gcc" if backend == "avr" else "gcc") is None:
        pytest.skip(f"no compiler to build the {backend} board")
    trace = tmp_path / "trace.jsonl"
    program = Path(sys.executable).parent / "protoduino"
    cmd = [str(program), "console", "--sim", backend, "--trace", str(trace)]
    cmd += ["--http-port", "0", "--token", "tok", "--foxglove", "0"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        lines: list[str] = []
        while not any("Foxglove on ws://" in line for line in lines):
            line = proc.stdout.readline()  # bounded by the test's timeout
            assert line, f"exited: {lines}"
            lines.append(line)
        url = next(line for line in lines if "open http" in line).split("open ", 1)[1].strip()
        foxglove_url = lines[-1].split("Foxglove on ", 1)[1].strip()
        assert url.endswith("/?token=tok"), url
        base = url.split("?")[0]
        assert _status(base) == 403
        assert _status(url) == 200

        def led() -> list[int]:
            changes = [json.loads(line) for line in trace.read_text().splitlines()]
            return [c["value"] for c in changes if c["pin"] == 13]

        async def drive() -> dict[str, Any]:
            import aiohttp

            async with (
                aiohttp.ClientSession() as session,
                session.ws_connect(base + "ws?token=tok") as ws,
            ):
                state: dict[str, Any] = await ws.receive_json()
                await ws.send_json({"op": "beat"})
                await ws.send_json({"op": "write", "pin": 13, "value": 1})
                await asyncio.to_thread(until, lambda: led()[-1:] == [1], "the led on")
                # --foxglove: the live channels are served beside (test_foxglove_live.py).
                async with session.ws_connect(foxglove_url, protocols=("foxglove.sdk.v1",)) as fox:
                    hello = await fox.receive_json()
                    assert hello["op"] == "serverInfo", hello
                # Still beating (so no failsafe), the command is told to end.
                proc.send_signal(signal.SIGTERM)
                while not ws.closed:
                    await ws.send_json({"op": "beat"})
                    with contextlib.suppress(asyncio.TimeoutError):
                        await ws.receive(timeout=0.2)
                return state

        state = asyncio.run(drive())
        assert [o["name"] for o in state["outputs"]] == [
            "left motor",
            "pan",
            "tilt",
            "right motor",
            "led",
        ]
        assert [i["mode"] for i in state["inputs"]] == ["counter", "input", "analog"]
        assert state["role"] == "driver"
        assert proc.wait(30) == 0
        assert proc.stderr is not None and "stopped" in proc.stderr.read()
        assert led()[-1] == 0  # the console's Stop before it closed
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
