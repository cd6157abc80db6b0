"""Make docs/console.png: the console at work on the example robot, in headless Chromium.

    python tools/console_screenshot.py [OUT]     # default docs/console.png

The simulated board runs the example robot (``protoduino console --sim``'s); its control
socket moves the battery's analog input, the bumper and the encoder while the page drives
the servos, the led and a motor, as tests/e2e/test_console.py does.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

from protoduino import Board
from protoduino.console import EXAMPLE_ROBOT, ConsoleServer, LiveBoard
from protoduino.simboard import SimBoard
from selenium import webdriver
from selenium.webdriver.chrome.options import Options
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

ROOT = Path(__file__).resolve().parents[1]


def main(out: Path) -> None:
    profile = tempfile.mkdtemp(prefix="protoduino-chromium-")
    options = Options()
    options.binary_location = shutil.which("chromium") or "chromium"
    for flag in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--window-size=1500,900",
        f"--user-data-dir={profile}",
    ):
        options.add_argument(flag)
    with (
        SimBoard("native") as sim,
        Board.open(sim.start(), liveness="heartbeat", failsafe_timeout=2.0) as board,
    ):
        live = LiveBoard(board, window=30.0)
        live.configure_all(EXAMPLE_ROBOT)
        with ConsoleServer(live) as server:
            page = webdriver.Chrome(
                options=options, service=Service(shutil.which("chromedriver") or "chromedriver")
            )
            try:
                page.get(server.url)
                time.sleep(1.0)
                page.find_element(By.ID, "toggle-13").click()
                ActionChains(page).drag_and_drop_by_offset(
                    page.find_element(By.ID, "servo-9"), -50, 0
                ).perform()
                ActionChains(page).drag_and_drop_by_offset(
                    page.find_element(By.ID, "pwm-3"), 40, 0
                ).perform()
                for step in range(40):
                    sim.set_analog(14, 600 + (step * 37) % 200)
                    if step % 10 == 0:
                        sim.set_level(7, step % 20)
                        sim.pulses(2, 20, 200)
                    time.sleep(0.15)
                page.save_screenshot(str(out))
            finally:
                page.quit()
        live.close()
    shutil.rmtree(profile, ignore_errors=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "console.png")
