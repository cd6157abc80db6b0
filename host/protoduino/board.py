"""The Board API: a device's pins (servos, digital and PWM outputs, inputs) over a reliable link.

``Board.open(url)`` opens the port, handshakes, asks the device for its
:class:`DeviceInfo` and starts the 1 Hz Ping. Every command returns once the
device acknowledged it and raises otherwise:

* arguments are checked first, against the device's own figures, and refused
  with the :class:`CommandRejectedError` status the device would give
  (``sent=False``, nothing sent);
* the device's refusal raises :class:`CommandRejectedError` (``sent=True``);
* no Ack after every retry raises :class:`AckTimeoutError` (a ``TimeoutError``);
* a link that is down and does not come back in time raises the link's error
  (:class:`TransportError`, :class:`HandshakeError`, ...).

Sessions: every board is one host session (a random id, or ``session=``
to take over where another process left off, as the command line does).
The device keeps a session's outputs across a re-handshake of the same
session (a reconnect) and releases them for a new one.

Restore policy: the board remembers every Init it sent and the last value
acknowledged for each output. When the device loses them (it rebooted, or
another session took it over), every call still outstanding fails with
:class:`DeviceRebootedError`, a REBOOTED (or SESSION_LOST) event tells the
application, and the board re-initialises every output, which comes up at
its safe value. With ``restore="last"`` it then sends each last value again.
A reboot loop (``reboot_limit`` losses within ``reboot_window`` seconds)
stops restoring: every call then raises :class:`RebootLoopError`. A Stop or a
failsafe forgets the values (the device latched its outputs safe; a restore
must not undo that).

Non-blocking calls: every command also has a ``submit`` form that returns a
:class:`concurrent.futures.Future` at once, resolved by the Ack with the same
value or error the blocking call returns or raises; arguments are checked
before anything is sent, so a bad one raises at once, as in the blocking call.
A future without a done-callback is resolved as its Ack is read (on the I/O
thread: a caller blocked in ``result()`` wakes without a hop through the event
thread); one with a done-callback is resolved on the event thread, its callbacks
with it, in the order the Acks arrived and in order with the events (never on
the I/O thread: a slow done-callback must not stall the link, and a callback may
command the board, even blocking). A submitted command cannot be recalled:
``future.cancel()`` returns False.

Threads per board: the transport's I/O thread and one event thread that runs
the ``on_event`` callbacks and the futures' done-callbacks. Both stop in
:meth:`Board.close`.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Literal, SupportsFloat, TypeVar

from ._generated import protoduino_pb2 as pb
from .arguments import (
    Pin,
    RealNumber,
    check_failsafe_ms,
    check_session,
    pin_number,
    refused,
)
from .boardoptions import BoardOptions, Liveness, RestorePolicy, resolved

# Public here too, where it began (an explicit re-export).
from .boardoptions import OpenCancel as OpenCancel  # noqa: PLC0414
from .capture import CaptureWriter
from .closing import ClosedOnExit
from .commands import DIGITAL_INPUT, PWM, SERVO, PinMode, feature_hint
from .constants import PING_INTERVAL, SERVO_DEFAULT_MAX_US, SERVO_DEFAULT_MIN_US
from .errors import (
    ArgumentError,
    ArgumentTypeError,
    BoardClosedError,
    CommandRejectedError,
    FeatureMissingError,
    ProtocolError,
    ProtoduinoError,
    ReentrantCallError,
    UserError,
    UserReplyLostError,
)
from .events import Event, EventCallback, EventDispatcher, EventKind, EventThreadFuture, Stats
from .inputs import InputTable
from .link import Link
from .messages import (
    PIN_SET_PINS,
    ArduinoIn,
    ArduinoOut,
    InputKind,
    Status,
    pin_set,
    status_name,
)

# Each pin mode's host code is a module of its own (protoduino.modes), which the board
# composes; its names are public here too, as before (explicit re-exports).
from .modes import analog_input, counter, digital, digital_input, pwm, servo
from .modes.analog_input import AnalogInput as AnalogInput  # noqa: PLC0414
from .modes.base import PinRecord
from .modes.counter import Counter as Counter  # noqa: PLC0414
from .modes.counter import Edge as Edge  # noqa: PLC0414
from .modes.digital import DigitalOutput as DigitalOutput  # noqa: PLC0414
from .modes.digital_input import DigitalInput as DigitalInput  # noqa: PLC0414
from .modes.digital_input import Interlock as Interlock  # noqa: PLC0414
from .modes.pwm import PwmOutput as PwmOutput  # noqa: PLC0414
from .modes.servo import FRAMES_PER_SECOND as FRAMES_PER_SECOND  # noqa: PLC0414
from .modes.servo import MAX_SPEED_US as MAX_SPEED_US  # noqa: PLC0414
from .modes.servo import Servo as Servo  # noqa: PLC0414
from .modes.servo import effective_speed as effective_speed  # noqa: PLC0414
from .readback import DeviceInfo as DeviceInfo  # noqa: PLC0414
from .readback import OutputState as OutputState  # noqa: PLC0414
from .readback import decode_device_info, failsafe_cause
from .readback import decode_output_states as decode_output_states  # noqa: PLC0414
from .rpc import Ack, Call, Rpc, RpcState
from .transport import FrameMonitor
from .userreports import UserReportTable
from .wiring import Wiring, serial_wiring

if TYPE_CHECKING:
    from typing_extensions import Unpack

log = logging.getLogger(__name__)

#: Ping payloads are bounded by the schema (protoduino.options: 64 bytes).
MAX_PING_PAYLOAD = 64

#: A Pose's most items (protoduino.options: Pose.items max_count): its servos and PWM outputs.
MAX_POSE_ITEMS = 8
#: Pins a Pose's digital pin sets hold (Pose.digital_pins: bytes, 9 at most, protocol version 8).
POSE_MASK_PINS = PIN_SET_PINS

T = TypeVar("T")

#: A pose's value for one output: degrees (any real number) or a digital level.
PoseValue = SupportsFloat | bool


def _no_value(call: Call) -> None:
    call.result()  # raises the call's error, if any


def _returning(obj: T) -> Callable[[Call], T]:
    def value(call: Call) -> T:
        call.result()
        return obj

    return value


def _user_call(method: int, request: bytes) -> ArduinoIn:
    if isinstance(method, bool) or not isinstance(method, int) or not 1 <= method <= 255:
        raise ArgumentError(f"user method must be 1..255, not {method!r}")
    msg = ArduinoIn()
    msg.user_call.method = method
    msg.user_call.request = bytes(request)
    return msg


def _user_reply(call: Call) -> bytes:
    """A UserCall's reply; its handler's own refusal as :class:`UserError`."""
    if call.error is not None:
        refusal = call.refusal
        if refusal is not None and refusal.status == Status.STATUS_USER_ERROR:
            raise UserError(
                refusal.user_code,
                f"user method refused by its handler with code {refusal.user_code}",
            ) from call.error
        raise call.error
    ack = call.result()
    if ack.WhichOneof("result") != "user_reply":
        raise UserReplyLostError(
            "the user call ran once, but its reply was lost (its retransmission was "
            "answered from the device's dedupe window, which keeps no replies)"
        )
    return bytes(ack.user_reply)


def _output_states(call: Call) -> dict[int, OutputState]:
    return decode_output_states(call.result().outputs)


#: The automatic Ping comes at least this many times per failsafe timeout.
PINGS_PER_TIMEOUT = 4


def incapable(info: DeviceInfo, pin: int, mode: PinMode) -> CommandRejectedError | None:
    """Why ``pin`` cannot do ``mode`` on this board, as the device's pin table says
    (``info.can``: no PWM, ADC or interrupt there, or no digital I/O at all, as the
    Nano's A6 and A7); None if it can."""
    if info.can(pin, mode):
        return None
    capable = info.pins_for(mode)
    return refused(
        Status.STATUS_NOT_SUPPORTED,
        f"pin {pin} cannot be {mode.a_pin} on this "
        f"{info.board} (those are {', '.join(map(str, capable)) or 'none'})",
    )


def conflict(
    info: DeviceInfo, pin: int, mode: PinMode, held: Mapping[int, PinMode]
) -> CommandRejectedError | None:
    """Why configuring ``pin`` as ``mode`` is refused while the pins of ``held`` are
    configured (pin -> mode), in the device's order (docs/protocol.md section 7, rule 13);
    None if nothing rules it out. The same mode again is a new configuration, not a conflict.

    A servo while a pin does PWM on the servos' timer (the timer would have to do both),
    then a pin that cannot do the mode (:func:`incapable`), then the pin itself held by
    another mode, then PWM on the servos' timer while a servo runs: the pins and timers as
    the device's pin table says (``info``). The board checks what it
    configured with it; ``protoduino``'s commands, which resume a session an earlier
    command configured, explain the device's own refusal with it from what the device says
    it drives (``read_outputs``).
    """
    if mode is SERVO:
        pwm = [p for p in info.timer_pins("servos") if held.get(p) is PWM]
        if pwm:  # checked before the pin itself, as the device does
            return refused(
                Status.STATUS_TIMER_IN_USE,
                f"pin {pwm[0]} does PWM on Timer{info.timer(pwm[0])}, the timer the servos "
                "need (release it first)",
            )
    cannot = incapable(info, pin, mode)
    if cannot is not None:
        return cannot
    current = held.get(pin)
    if current is not None and current is not mode:
        return refused(Status.STATUS_PIN_IN_USE, f"pin {pin} is {current.a_pin}")
    timer = info.timer(pin)
    if mode is PWM and timer is not None and info.timer_use(timer) == "servos":
        servo = min((p for p, m in held.items() if m is SERVO), default=None)
        if servo is not None:
            return refused(
                Status.STATUS_TIMER_IN_USE,
                f"pin {pin}'s PWM needs Timer{timer}, which makes the servo pulses while a "
                f"servo runs (pin {servo}; release the servos first, or use another PWM pin)",
            )
    return None


#: What a pose sets.
PoseOutput = Servo | DigitalOutput | PwmOutput


class Board(ClosedOnExit):
    """A connected device. Use :meth:`open`; close it (or use ``with``) when done."""

    def __init__(
        self, url: str, *, wiring: Wiring | None = None, **options: Unpack[BoardOptions]
    ) -> None:
        """See :meth:`open`. ``wiring`` is what the board runs on (:mod:`protoduino.wiring`):
        by default the pyserial port ``url`` and the board's threads; :mod:`protoduino.testing`
        passes an in-process device's."""
        # One declaration of the options (boardoptions.py); an unknown one raises here.
        opts = resolved(options)
        ack_timeout, max_retries, window = opts["ack_timeout"], opts["max_retries"], opts["window"]
        handshake_timeout, watchdog_timeout = opts["handshake_timeout"], opts["watchdog_timeout"]
        failsafe_timeout, session = opts["failsafe_timeout"], opts["session"]
        liveness, restore, cancel = opts["liveness"], opts["restore"], opts["cancel"]
        capture, capture_max_bytes = opts["capture"], opts["capture_max_bytes"]
        reboot_limit, reboot_window = opts["reboot_limit"], opts["reboot_window"]
        baudrate, ping, monitor = opts["baudrate"], opts["ping"], opts["monitor"]
        # Every option is checked before anything is opened or started: a wrong one
        # raises here, with no thread to stop (a float session once crashed the I/O thread).
        failsafe_ms = check_failsafe_ms(failsafe_timeout)
        if session is not None:
            session = check_session(session)
        if liveness not in ("ping", "heartbeat"):
            raise ArgumentError(f"liveness must be 'ping' or 'heartbeat', not {liveness!r}")
        if restore not in ("safe", "last"):
            raise ArgumentError(f"restore must be 'safe' or 'last', not {restore!r}")
        if capture_max_bytes is not None and capture is None:
            raise ArgumentError("capture_max_bytes bounds a capture: give capture= too")
        if wiring is None:
            wiring = serial_wiring(url, baudrate)
        self.failsafe_timeout = failsafe_ms / 1000
        self.liveness: Liveness = liveness
        self.restore: RestorePolicy = restore
        self.url = url
        self._lock = threading.Lock()
        self._outputs: dict[int, PinRecord] = {}
        #: The failsafe as last reported to the application: whether a safe state
        #: holds, and the device's epoch for it (each is reported once, whether its
        #: event arrived or a liveness Ack told of it).
        self._failsafe_active = False
        self._failsafe_epoch: int | None = None
        self._closed = False
        self._rpc = Rpc(
            notify=self._notify,
            ack_timeout=ack_timeout,
            max_retries=max_retries,
            window=window,
            ping=ping,
            # A missed Ping or two must not trip a short failsafe.
            ping_interval=min(PING_INTERVAL, self.failsafe_timeout / PINGS_PER_TIMEOUT),
            link_wait=handshake_timeout,
            reboot_limit=reboot_limit,
            reboot_window=reboot_window,
            failsafe_timeout=self.failsafe_timeout,
            heartbeat_liveness=liveness == "heartbeat",
            clock=wiring.clock,
            waiter=wiring.wait,
            message_hook=self._message,
            restore_provider=self._restore_messages,
            restore_values=restore == "last",
        )
        # Before the port: a capture that cannot be written fails with nothing opened,
        # and the handshake is in it. Its hooks are called only once frames flow (from the
        # link's open on), when the link, the inputs and the event thread all exist.
        self._capture = (
            CaptureWriter(
                capture,
                url,
                max_bytes=capture_max_bytes,
                stats=lambda: self.stats,
                on_lost=self._capture_lost,
            )
            if capture is not None
            else None
        )
        self._transport = wiring.port
        if monitor is not None:
            self._transport.add_monitor(monitor)
        if self._capture is not None:
            self._transport.add_monitor(self._capture.frame)
        self._link = Link(
            self._transport,
            self._rpc,
            handshake_timeout=handshake_timeout,
            watchdog_timeout=watchdog_timeout,
            notify=self._notify,
            session=session,
            baudrate=baudrate,
            clock=wiring.clock,
            next_id=self._rpc.next_message_id,
            silence_timeout=2 * ack_timeout,
        )
        self._rpc.attach(self._link)
        # Started only now: a constructor above that refuses its options leaves no thread.
        self._events = wiring.events()
        # Callbacks of inputs run on the event thread, in order with the events.
        self._inputs = InputTable(
            self._events.put_job, wiring.clock, wait=wiring.wait if wiring.inline else None
        )
        # The user service's reports (docs/services.md), newest wins as the inputs'.
        self.user_reports = UserReportTable(self._events.put_job)
        # From here on anything that ends the open early (an error, a KeyboardInterrupt
        # at any point, a cancel from another thread) closes what was started: a
        # half-open board that pinged on would keep the device's outputs driven.
        try:
            if cancel is not None:
                cancel._attach(self)
            self._link.open()
            self.info = self._get_info()
            self._rpc.rx_budget = self.info.rx_buffer or None
            self._send(self._failsafe_config())
        except BaseException:
            self.close()
            raise

    @classmethod
    def open(cls, url: str, **options: Unpack[BoardOptions]) -> Board:
        """Open ``url`` (any pyserial URL), handshake and read the device's info.

        Raises :class:`TransportError` if the port cannot be opened,
        :class:`HandshakeError` if the device does not answer within
        ``handshake_timeout``, :class:`VersionMismatchError` or
        :class:`SchemaMismatchError` if it runs incompatible firmware.

        ``ack_timeout`` and ``max_retries`` bound each command; ``window`` is
        how many commands may await their Ack at once; ``ping=False`` starts
        without the automatic Ping (see :attr:`pinging`); ``monitor`` is
        called with every frame in both directions from the first one on
        (on the I/O thread: be quick); ``capture`` is a file that records every
        frame in both directions with its time, the link counters and the events
        (:mod:`protoduino.capture`; ``protoduino decode`` reads it, ``protoduino
        monitor --follow`` shows it live), raising :class:`CaptureError` if it
        cannot be created; a write that fails later (a full disk) stops the
        capture, not the board: one :attr:`EventKind.CAPTURE_LOST` event, and
        ``stats.capture_lost`` counts what was not recorded;
        ``capture_max_bytes`` rotates it (PATH.1) before it grows past that
        many bytes; ``watchdog_timeout`` is how long the device may stay
        silent while answers are due before the link handshakes again.

        ``failsafe_timeout`` (seconds, 0.1..60) is how long the device keeps
        commanded outputs without a sign of life before it drives them safe;
        the automatic Ping then comes every ``min(1 s, failsafe_timeout / 4)``.
        ``liveness="heartbeat"`` makes only :meth:`heartbeat` count as that
        sign of life (the automatic Ping then only keeps the link up), so a
        control loop that hangs trips the failsafe, not only a dead process.

        ``restore`` says what happens when the device lost the outputs (it
        rebooted, or another session took it over): ``"safe"`` re-initialises
        them (each at its safe value); ``"last"`` also sends each output's
        last acknowledged value again. Either way calls outstanding at that
        moment fail with :class:`DeviceRebootedError`; ``reboot_limit``
        losses within ``reboot_window`` seconds stop restoring
        (:class:`RebootLoopError`).

        ``baudrate`` pins the line rate: the port opens at it and stays there (a
        firmware built with another opening rate, or a line known to carry no more).
        By default (None) the port opens at 115200 baud and the host and the device
        agree on the fastest rate both offer (docs/protocol.md 5, *Line rate*): on an
        Uno 1,000,000 baud; a rate the line fails to carry falls back to a slower one.
        :attr:`baudrate` is the rate the line runs at.

        ``session`` resumes a host session (1..2**32-1) that may still own
        the device's outputs, as the command line does; by default every
        board is a new session, which releases whatever another session had
        configured.

        ``cancel`` (an :class:`OpenCancel`) lets another thread abandon the open.
        However it ends early (an error, a ``KeyboardInterrupt`` at any point, a
        cancel), nothing of the board is left running: no thread, no Ping, and
        the port is free again. Options are checked before anything starts: a
        wrong type raises :class:`ArgumentTypeError`, a wrong value
        :class:`ArgumentError`.
        """
        return cls(url, **options)

    # --- context and life cycle -------------------------------------------------------

    def close(self) -> None:
        """Stop pinging, fail outstanding calls, stop every thread, close the port.

        Idempotent, and callable from an event callback. The device is left as
        it is: with pings gone, its failsafe drives the outputs safe after
        FAILSAFE_TIMEOUT. No event callback starts once close() was called
        (events still queued are discarded; futures are still resolved, with
        BoardClosedError for calls that had not completed); one that is running
        is waited for up to CLOSE_WAIT (1 s), then left to finish (see
        :class:`EventDispatcher`). So close() returns within about 1 s plus the
        I/O thread's stop (at once, or 2 s for a wedged port driver).
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
        # Each step runs even if one before it was interrupted (a second Ctrl-C while an
        # open that the first one cut short closes): no thread may be left behind.
        try:
            self._rpc.close()
            self._inputs.close()
            self._link.close()
        finally:
            try:
                if self._capture is not None:
                    self._capture.close()  # after the I/O thread stopped: the last frame is in
            finally:
                self._events.close()

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def session(self) -> int:
        """This board's host session id: pass it as ``session=`` to resume the session
        (and keep the device's outputs) from another board or process."""
        return self._link.session

    def __repr__(self) -> str:
        return f"Board({self.url!r}, state={self._link.state.value})"

    # --- outputs ------------------------------------------------------------------------

    def servo(
        self,
        pin: Pin,
        safe: int | Literal["detach"] | None = None,
        *,
        safe_us: int | None = None,
        min_us: int = SERVO_DEFAULT_MIN_US,
        max_us: int = SERVO_DEFAULT_MAX_US,
        max_speed: float | None = None,
        max_speed_us: int | None = None,
    ) -> Servo:
        """Configure ``pin`` as a servo; it moves to its safe position at once.

        ``safe`` is in degrees (90 if neither it nor ``safe_us`` is given);
        ``safe_us`` gives it in microseconds instead; ``safe="detach"`` makes
        the safe state no pulses at all (the servo goes limp, and starts so).
        The failsafe and :meth:`stop` return the servo there. Calling it again
        for the same pin changes the limits and the safe state; with the same
        ones it changes nothing at the pin (no detour through the safe value).

        ``max_speed`` (degrees per second) or ``max_speed_us`` (us per second)
        limits its speed on the device: every later value (write, pose, stop,
        failsafe) is approached one step per 20 ms servo frame. The device keeps
        a whole number of us per frame (:func:`effective_speed`, in
        ``Servo.max_speed_us``), at most 12750 us/s.
        """
        msg, on_ok, made = servo.init(
            self, pin, safe, safe_us, min_us, max_us, max_speed, max_speed_us
        )
        self._send(msg, on_ok)
        return made

    def submit_servo(
        self,
        pin: Pin,
        safe: int | Literal["detach"] | None = None,
        *,
        safe_us: int | None = None,
        min_us: int = SERVO_DEFAULT_MIN_US,
        max_us: int = SERVO_DEFAULT_MAX_US,
        max_speed: float | None = None,
        max_speed_us: int | None = None,
    ) -> Future[Servo]:
        """:meth:`servo` without waiting: a future of the :class:`Servo`, resolved by the Ack."""
        msg, on_ok, made = servo.init(
            self, pin, safe, safe_us, min_us, max_us, max_speed, max_speed_us
        )
        return self._future(msg, on_ok, _returning(made))

    def digital_output(self, pin: Pin, safe: bool = False) -> DigitalOutput:
        """Configure ``pin`` as a digital output; it takes its ``safe`` level at once.

        Again with the same ``safe`` level, it changes nothing at the pin.
        """
        msg, on_ok, output = digital.init(self, pin, safe)
        self._send(msg, on_ok)
        return output

    def submit_digital_output(self, pin: Pin, safe: bool = False) -> Future[DigitalOutput]:
        """:meth:`digital_output` without waiting: a future of the output, resolved by the Ack."""
        msg, on_ok, output = digital.init(self, pin, safe)
        return self._future(msg, on_ok, _returning(output))

    def pwm_output(self, pin: Pin, safe: RealNumber = 0) -> PwmOutput:
        """Configure ``pin`` as a PWM output (duty 0..255); it takes its ``safe`` duty at once.

        The failsafe, :meth:`stop` and an interlock drive it back to ``safe`` (0,
        off, suits a motor). Again with the same ``safe`` duty it changes nothing at
        the pin. Only the pins in ``info.pwm_pins`` can do PWM (the Uno's 3, 5, 6, 9,
        10, 11, at 976 Hz); pins 9 and 10 share Timer1 with the servos
        (:class:`TimerInUseError` while one runs).
        """
        msg, on_ok, output = pwm.init(self, pin, safe)
        self._send(msg, on_ok)
        return output

    def submit_pwm_output(self, pin: Pin, safe: RealNumber = 0) -> Future[PwmOutput]:
        """:meth:`pwm_output` without waiting: a future of the output, resolved by the Ack."""
        msg, on_ok, output = pwm.init(self, pin, safe)
        return self._future(msg, on_ok, _returning(output))

    # --- inputs ----------------------------------------------------------------------

    def digital_input(
        self,
        pin: Pin,
        *,
        pull_up: bool = False,
        debounce_ms: int = 0,
        interlock: Interlock | None = None,
    ) -> DigitalInput:
        """Configure ``pin`` as a digital input; returns once its first level is known.

        ``pull_up`` turns on the pin's pull-up (a switch to ground then reads
        False when closed); ``debounce_ms`` (0..255) is how long a level must
        hold on the device before it counts. ``interlock="low"`` (or ``"high"``)
        makes it an interlock: when its debounced level reaches that level, the
        device itself drives every output safe at once, latches (a FAILSAFE event
        with cause ``"interlock"`` and this pin), and refuses new values with
        :class:`InterlockActiveError` until the input is back at its other level
        and :meth:`clear_interlock` was called.
        """
        msg, on_ok, make = digital_input.init(self, pin, pull_up, debounce_ms, interlock)
        return self._input(msg, on_ok, make)

    def submit_digital_input(
        self,
        pin: Pin,
        *,
        pull_up: bool = False,
        debounce_ms: int = 0,
        interlock: Interlock | None = None,
    ) -> Future[DigitalInput]:
        """:meth:`digital_input` without waiting, resolved by the Ack (before the first level:
        ``read()`` is None until it arrives, right after)."""
        msg, on_ok, make = digital_input.init(self, pin, pull_up, debounce_ms, interlock)
        return self._future(msg, on_ok, _returning(make()))

    def analog_input(
        self, pin: Pin, *, rate_hz: float = 100.0, threshold: int = 0, heartbeat: float = 1.0
    ) -> AnalogInput:
        """Configure analog input ``pin`` (``info.analog_pins``; A0 is 14 on the Uno).

        The device samples it ``rate_hz`` times a second (it keeps a whole
        number of ms between samples, 1..60000) and reports a sample that moved
        by more than ``threshold`` counts (0..1023), or the value again when
        ``heartbeat`` seconds passed without a report (so silence still says the
        device is alive). Returns once its first value is known.
        """
        msg, on_ok, make = analog_input.init(self, pin, rate_hz, threshold, heartbeat)
        return self._input(msg, on_ok, make)

    def submit_analog_input(
        self, pin: Pin, *, rate_hz: float = 100.0, threshold: int = 0, heartbeat: float = 1.0
    ) -> Future[AnalogInput]:
        """:meth:`analog_input` without waiting, resolved by the Ack."""
        msg, on_ok, make = analog_input.init(self, pin, rate_hz, threshold, heartbeat)
        return self._future(msg, on_ok, _returning(make()))

    def counter(
        self, pin: Pin, *, edge: Edge = "rising", pull_up: bool = False, rate_hz: float = 50.0
    ) -> Counter:
        """Count ``edge`` edges on ``pin`` (``info.counter_pins``) in an interrupt.

        The count (since this Init; wraps at 2**32) is reported when it changed,
        at most ``rate_hz`` times a second (the Uno: pins 2..13, two counters at once).
        Returns once its first count (0) is known.
        """
        msg, on_ok, make = counter.init(self, pin, edge, pull_up, rate_hz)
        return self._input(msg, on_ok, make)

    def submit_counter(
        self, pin: Pin, *, edge: Edge = "rising", pull_up: bool = False, rate_hz: float = 50.0
    ) -> Future[Counter]:
        """:meth:`counter` without waiting, resolved by the Ack."""
        msg, on_ok, make = counter.init(self, pin, edge, pull_up, rate_hz)
        return self._future(msg, on_ok, _returning(make()))

    def _input_recorder(
        self, pin: int, mode: PinMode, msg: ArduinoIn, kind: InputKind
    ) -> Callable[[], None]:
        """Check the pin is free for input ``mode``; what to record at the Init's Ack (its
        reports carry ``kind`` values)."""
        with self._lock:
            self._check_free(pin, mode)
        state = PinRecord(mode, msg.SerializeToString(), 0)

        def on_ok() -> None:
            self._set_output(pin, state)
            self._inputs.configure(kind, pin)  # the next report is the new configuration's

        return on_ok

    def _input(self, msg: ArduinoIn, on_ok: Callable[[], None], make: Callable[[], T]) -> T:
        """Send an input's Init, then wait (up to :attr:`round_time`) for its first value.

        The device reports the value right after the Init's Ack. Should that report
        be lost on the line, the input is still configured: ``read()`` says None
        until the next report (a change, or an analog input's heartbeat).
        """
        self._send(msg, on_ok)
        created = make()
        assert isinstance(created, DigitalInput | AnalogInput | Counter)
        with contextlib.suppress(ProtoduinoError):
            created._wait(lambda _reading: True, self.round_time)
        return created

    def clear_interlock(self) -> None:
        """Clear a latched interlock, once its input is back at its normal level.

        Refused with :class:`InterlockActiveError` while the input is still at its
        trip level. The outputs stay at their safe values until commanded again.
        """
        self._send(self._clear_interlock_msg())

    def submit_clear_interlock(self) -> Future[None]:
        """:meth:`clear_interlock` without waiting: a future resolved by the Ack."""
        return self._future(self._clear_interlock_msg(), None, _no_value)

    def _clear_interlock_msg(self) -> ArduinoIn:
        if self._closed:
            raise BoardClosedError("the board is closed")
        self._check_feature(DIGITAL_INPUT)
        msg = ArduinoIn()
        msg.clear_interlock.SetInParent()
        return msg

    # --- board-wide commands -------------------------------------------------------

    def ping(self, payload: bytes = b"") -> float:
        """Round trip of one Ping (seconds); the device echoes ``payload`` (<= 64 bytes)."""
        msg, rtt = self._ping(payload)
        return rtt(self._send(msg))

    def submit_ping(self, payload: bytes = b"") -> Future[float]:
        """:meth:`ping` without waiting: a future of the round trip, resolved by the Ack."""
        msg, rtt = self._ping(payload)
        return self._future(msg, None, rtt)

    def _ping(self, payload: object) -> tuple[ArduinoIn, Callable[[Call], float]]:
        if not isinstance(payload, bytes | bytearray | memoryview):  # bytes(5) is 5 zeros
            raise ArgumentTypeError(f"payload must be bytes, not {type(payload).__name__}")
        sent = bytes(payload)
        if len(sent) > MAX_PING_PAYLOAD:
            raise refused(
                Status.STATUS_DECODE_ERROR,
                f"ping payload of {len(sent)} bytes exceeds {MAX_PING_PAYLOAD}",
            )
        msg = ArduinoIn()
        msg.ping.payload = sent

        def rtt(call: Call) -> float:
            echo = bytes(call.result().ping_echo)
            if echo != sent:
                raise ProtocolError(f"ping echo differs: sent {sent.hex()}, got {echo.hex()}")
            assert call.rtt is not None
            return call.rtt

        return msg, rtt

    def heartbeat(self) -> None:
        """The application's sign of life: restarts the device's failsafe timer.

        With ``liveness="heartbeat"`` it is the only thing that does: call it
        from the control loop, more often than ``failsafe_timeout``.
        """
        self._send(self._heartbeat_msg())

    def submit_heartbeat(self) -> Future[None]:
        """:meth:`heartbeat` without waiting: a future resolved by the Ack.

        The sign of life is the message reaching the device, so a control loop
        that must not block (an asyncio loop, a real-time thread) calls this
        and carries on; a failed future says the heartbeat did not arrive.
        """
        return self._future(self._heartbeat_msg(), None, _no_value)

    def _heartbeat_msg(self) -> ArduinoIn:
        if self._closed:
            raise BoardClosedError("the board is closed")
        msg = ArduinoIn()
        msg.heartbeat.SetInParent()
        return msg

    def release(self, pin: Pin) -> None:
        """Release an output: a servo's pulses stop, a digital pin becomes an input.

        The pin is then free for any mode (and a servo's slot for another pin).
        """
        self._send(*self._release(pin))

    def submit_release(self, pin: Pin) -> Future[None]:
        """:meth:`release` without waiting: a future resolved by the Ack."""
        return self._future(*self._release(pin), _no_value)

    def _release(self, pin: Pin) -> tuple[ArduinoIn, Callable[[], None]]:
        pin = self._check_pin(pin)
        with self._lock:
            if pin not in self._outputs:
                raise refused(Status.STATUS_NOT_INITIALISED, f"pin {pin} is not configured")
        msg = ArduinoIn()
        msg.release.pin = pin

        def forget() -> None:
            self._outputs.pop(pin, None)
            self._inputs.forget(pin)

        return msg, forget

    def release_all(self) -> None:
        """Release every output: the device is as unconfigured as after power-up."""
        self._send(*self._release_all())

    def submit_release_all(self) -> Future[None]:
        """:meth:`release_all` without waiting: a future resolved by the Ack."""
        return self._future(*self._release_all(), _no_value)

    def _release_all(self) -> tuple[ArduinoIn, Callable[[], None]]:
        if self._closed:
            raise BoardClosedError("the board is closed")
        msg = ArduinoIn()
        msg.release_all.SetInParent()

        def forget() -> None:
            self._outputs.clear()
            self._inputs.clear()

        return msg, forget

    def stop(self) -> None:
        """Emergency stop: every configured output to its safe value at once, latched."""
        self._send(self._stop_msg(), self._forget_values)

    def submit_stop(self) -> Future[None]:
        """:meth:`stop` without waiting: a future resolved by the Ack."""
        return self._future(self._stop_msg(), self._forget_values, _no_value)

    @staticmethod
    def _stop_msg() -> ArduinoIn:
        msg = ArduinoIn()
        msg.stop.SetInParent()
        return msg

    def pose(self, targets: Mapping[PoseOutput, PoseValue]) -> None:
        """Set several outputs in one command, all or nothing.

        ``targets`` maps each output to its value: degrees for a :class:`Servo`
        (any real number, rounded as :meth:`Servo.write` rounds), a level for a
        :class:`DigitalOutput`, a duty for a :class:`PwmOutput`. At most 8 servos
        and PWM outputs, and any number of digital outputs (they travel as two
        pin sets, a few bytes for all of them). The device checks every value
        before it applies any; the servos' new widths start at the same servo
        frame (digital levels change at once, as the command runs). Whatever the
        order given, the device sets the PWM duties of 0 first, then the digital
        levels, then the other duties and the servos: a motor the pose stops stops
        before its direction pin changes, one it starts starts after (never the
        wrong way on an H-bridge; docs/protocol.md, *Pose*). A refusal, on
        the host or by the device, raises :class:`CommandRejectedError` whose
        ``output`` is the offending output.
        """
        msg, on_ok, value = self._pose(targets)
        call = self._submit(msg, on_ok)
        with contextlib.suppress(ProtoduinoError):  # raised again below, the output named
            self._rpc.wait(call)
        value(call)

    def submit_pose(self, targets: Mapping[PoseOutput, PoseValue]) -> Future[None]:
        """:meth:`pose` without waiting: a future resolved by the Ack."""
        msg, on_ok, value = self._pose(targets)
        return self._future(msg, on_ok, value)

    def _pose(
        self, targets: Mapping[PoseOutput, PoseValue]
    ) -> tuple[ArduinoIn, Callable[[], None], Callable[[Call], None]]:
        if self._closed:
            raise BoardClosedError("the board is closed")
        if not isinstance(targets, Mapping):
            raise ArgumentTypeError(
                f"a pose is a mapping of outputs to values, not {type(targets).__name__}"
            )
        if not targets:
            raise refused(Status.STATUS_INVALID_ARGUMENT, "a pose sets at least one output")
        msg = ArduinoIn()
        pose = msg.pose
        # The device's order (protocol.md section 7, rule 7), which Ack.refused_item counts
        # in from 1: the items as listed, then the pin sets' pins upwards.
        items: list[PoseOutput] = []
        masked: dict[int, DigitalOutput] = {}
        pins = levels = 0
        seen: set[int] = set()
        records: list[tuple[int, bytes, int]] = []  # pin, its Control (for a restore), value
        for output, target in targets.items():
            if not isinstance(output, Servo | DigitalOutput | PwmOutput):
                raise ArgumentTypeError(
                    f"a pose sets Servo, DigitalOutput and PwmOutput objects, not {output!r}"
                )
            if output.board is not self:
                raise ArgumentError(f"{output!r} belongs to another board")
            try:
                if output.pin in seen:
                    raise refused(Status.STATUS_INVALID_ARGUMENT, f"pin {output.pin} twice")
                if isinstance(output, DigitalOutput) and output.pin < POSE_MASK_PINS:
                    control, width = output._pose_level(target)
                    pins |= 1 << output.pin
                    levels |= width << output.pin
                    masked[output.pin] = output
                else:
                    if len(items) == MAX_POSE_ITEMS:
                        raise refused(
                            Status.STATUS_INVALID_ARGUMENT,
                            f"a pose sets at most {MAX_POSE_ITEMS} servos and PWM outputs",
                        )
                    control, width = output._pose_item(pose.items.add(), target)
                    items.append(output)
            except CommandRejectedError as error:
                raise CommandRejectedError(
                    error.status, f"pose: {output!r}: {error}", sent=False, output=output
                ) from None
            except TypeError as error:
                raise ArgumentTypeError(f"pose: {output!r}: {error}") from None
            seen.add(output.pin)
            records.append((output.pin, control, width))
        pose.digital_pins = pin_set(pins)
        pose.digital_levels = pin_set(levels)
        outputs = items + [masked[pin] for pin in sorted(masked)]

        def on_ok() -> None:
            for pin, control, width in records:
                self._set_value(pin, control, width)

        def value(call: Call) -> None:
            try:
                call.result()
            except CommandRejectedError as error:
                index = call.refusal.refused_item if call.refusal is not None else 0
                if not 1 <= index <= len(outputs):
                    raise  # a repeated refusal (answered from the dedupe window) names none
                output = outputs[index - 1]
                raise CommandRejectedError(
                    error.status,
                    f"pose refused by the device at {output!r}: {status_name(error.status)}",
                    output=output,
                ) from None

        return msg, on_ok, value

    def read_outputs(self) -> dict[int, OutputState]:
        """What the device drives now, by pin: every configured output, even one this
        board did not configure (resuming a session, it sees the state it inherits; a
        new session has released everything)."""
        return _output_states(self._send(self._read_msg()))

    def submit_read_outputs(self) -> Future[dict[int, OutputState]]:
        """:meth:`read_outputs` without waiting."""
        return self._future(self._read_msg(), None, _output_states)

    @staticmethod
    def _read_msg() -> ArduinoIn:
        msg = ArduinoIn()
        msg.read_outputs.SetInParent()
        return msg

    @property
    def pinging(self) -> bool:
        """Whether the automatic 1 Hz Ping runs; set False to let the failsafe fire."""
        return self._rpc.pinging

    @pinging.setter
    def pinging(self, on: bool) -> None:
        self._rpc.pinging = on

    def on_event(self, callback: EventCallback) -> Callable[[], None]:
        """Call ``callback(event)`` for every :class:`Event`; returns an unsubscribe function.

        Callbacks run on the board's event thread, one at a time; they may
        command the board. Events wait for them in a bounded queue: see
        :class:`EventDispatcher` for what a slow callback loses.
        """
        return self._events.subscribe(callback)

    def add_frame_monitor(self, monitor: FrameMonitor) -> None:
        """See every frame in both directions (on the I/O thread: be quick).

        A monitor cannot make a blocking call on the board: it raises
        :class:`ReentrantCallError` at once (it would wait for an Ack that only
        the I/O thread, busy running the monitor, can read). A ``submit`` form
        returns at once and is allowed; waiting on its future there is not.
        """
        self._transport.add_monitor(monitor)

    @property
    def round_time(self) -> float:
        """How long a call may await its Ack once sent, every retry included:
        ``ack_timeout * (max_retries + 1)``."""
        return self._rpc.round_time

    @property
    def inputs(self) -> InputTable:
        """The latest value of every input the device reported (see :mod:`protoduino.inputs`)."""
        return self._inputs

    @property
    def call_timeout(self) -> float:
        """Longest a call takes to fail: its retries, plus waiting for a link that is down."""
        return self._rpc.call_timeout

    @property
    def events(self) -> EventDispatcher:
        """The board's event dispatcher: its thread, the events waiting and those dropped."""
        return self._events

    def rpc_state(self) -> RpcState:
        """A snapshot of the request layer's table (calls in flight, queued, the next id)."""
        return self._rpc.state()

    def request(self, msg: ArduinoIn) -> Ack:
        """Send one ArduinoIn exactly as given and return the device's Ack.

        Nothing is checked on the host and nothing is remembered for a reboot's
        restore: this is for a message the API has no method for, and for testing
        the device's own checks. Any status but OK raises
        :class:`CommandRejectedError`, as every command does.
        """
        return self._rpc.call(msg)

    def submit_request(self, msg: ArduinoIn) -> Future[Ack]:
        """:meth:`request` without waiting: a future of the Ack (or of its error)."""
        if self._closed:
            raise BoardClosedError("the board is closed")
        return self._future(msg, None, lambda call: call.result())

    def call_user(self, method: int, request: bytes) -> bytes:
        """Call method ``method`` of the firmware's user service; returns its reply bytes.

        ``request`` and the reply are messages of the user's schema, serialised: a
        generated client (``protoduino gen robot.proto``, docs/services.md) does both
        and checks the service's fingerprint first. Acknowledged and executed exactly
        once like every command. Raises :class:`UserError` (its ``code``) when the
        handler refuses, :class:`UserReplyLostError` when the call ran but its reply
        was lost, and the errors of any command.
        """
        call = self._start(_user_call(method, request))  # waited for here, as ping(): no hop
        with contextlib.suppress(ProtoduinoError):
            self._rpc.wait(call)  # its error stays the call's: _user_reply raises it, named
        return _user_reply(call)

    def submit_call_user(self, method: int, request: bytes) -> Future[bytes]:
        """:meth:`call_user` without waiting: a future of the reply bytes (or of its error)."""
        if self._closed:
            raise BoardClosedError("the board is closed")
        return self._future(_user_call(method, request), None, _user_reply)

    @property
    def baudrate(self) -> int:
        """The rate the line runs at: pinned, agreed (docs/protocol.md 5) or opening."""
        return self._transport.baudrate

    @property
    def stats(self) -> Stats:
        """A snapshot of the link counters."""
        link, rpc, tr, capture = self._link, self._rpc, self._transport, self._capture
        dropped = tr.decoder_counts
        dropped.pop("packets", None)
        if link.direction_drops:
            dropped["direction"] = link.direction_drops
        state = link.state.value
        if not tr.connected and state == "handshaking":
            state = "disconnected"
        return Stats(
            state=state,
            connected=tr.connected,
            rx_bytes=tr.rx_bytes,
            tx_bytes=tr.tx_bytes,
            rx_packets=link.rx_packets,
            tx_packets=tr.tx_packets,
            dropped=dropped,
            seq_lost=link.seq_lost,
            seq_desyncs=link.seq_desyncs,
            handshakes=link.handshakes,
            reconnects=link.reconnects,
            reboots=link.reboots,
            sessions_lost=link.sessions_lost,
            watchdog_resets=link.watchdog_resets,
            device_desyncs=link.device_events["desync"],
            device_rx_overflows=link.device_events["rx_overflow"],
            commands=rpc.commands,
            acks=rpc.acks,
            retransmits=rpc.retransmits,
            timeouts=rpc.timeouts,
            rejected=rpc.rejected,
            late_acks=rpc.late_acks,
            unknown_acks=rpc.unknown_acks,
            guard_holds=rpc.guard_holds,
            pings=rpc.pings,
            ping_failures=rpc.ping_failures,
            events_dropped=dict(self._events.dropped),
            capture_lost=capture.lost_records if capture is not None else 0,
            capture_lost_bytes=capture.lost_bytes if capture is not None else 0,
            capture_error=(
                (capture.error.strerror or str(capture.error))
                if capture is not None and capture.error is not None
                else None
            ),
            rtt=rpc.rtt,
            last_ping=rpc.last_ping,
            input_reports=self._inputs.reports,
            inputs_coalesced=self._inputs.coalesced,
            input_changes_skipped=self._inputs.skipped,
        )

    # --- internals ------------------------------------------------------------------------

    def pin_number(self, pin: object) -> int:
        """The number of ``pin``, given by number or by its name on the board as Arduino
        writes it: ``"A0"`` is the device's first analog input (``info.analog_pins``, 14 on
        the Uno). Every method that takes a pin takes either."""
        return pin_number(pin, self.info.analog_pins)

    def _check_pin(self, pin: object, mode: PinMode | None = None, *, reserved: bool = True) -> int:
        """The pin as an int (:meth:`pin_number`), checked as the device does first:
        ``mode``'s feature built in (rule 11), the pin's number, and (unless
        ``reserved=False``) not reserved."""
        pin = self.pin_number(pin)
        if self._closed:
            raise BoardClosedError("the board is closed")
        if mode is not None:
            self._check_feature(mode)
        if not 0 <= pin < self.info.num_pins:
            raise refused(
                Status.STATUS_INVALID_PIN,
                f"pin {pin} does not exist ({self.info.board}: 0..{self.info.num_pins - 1})",
            )
        if reserved:
            self._check_reserved(pin)
        return pin

    def _check_reserved(self, pin: int) -> None:
        if pin in self.info.reserved_pins:
            raise refused(Status.STATUS_RESERVED_PIN, f"pin {pin} is reserved")

    def _check_feature(self, mode: PinMode) -> None:
        if mode.feature not in self.info.features:
            raise FeatureMissingError(
                mode.feature,
                f"{mode.words}: {feature_hint(mode.feature)} "
                f"({status_name(Status.STATUS_NOT_SUPPORTED)})",
            )

    def _check_capable(self, pin: int, mode: PinMode) -> None:
        """``pin`` can do ``mode``, as the device's pin table says (:func:`incapable`)."""
        cannot = incapable(self.info, pin, mode)
        if cannot is not None:
            raise cannot

    def _check_free(self, pin: int, mode: PinMode) -> None:
        """Refuse what the pins this board configured rule out (lock held): :func:`conflict`."""
        held = {p: out.mode for p, out in self._outputs.items()}
        refusal = conflict(self.info, pin, mode, held)
        if refusal is not None:
            raise refusal

    def _control(self, pin: int, msg: ArduinoIn, value: int) -> None:
        if self._closed:
            raise BoardClosedError("the board is closed")
        payload = msg.SerializeToString()
        self._send(msg, lambda: self._set_value(pin, payload, value))

    def _control_future(self, pin: int, msg: ArduinoIn, value: int) -> Future[None]:
        if self._closed:
            raise BoardClosedError("the board is closed")
        payload = msg.SerializeToString()
        return self._future(msg, lambda: self._set_value(pin, payload, value), _no_value)

    def _send(self, msg: ArduinoIn, on_ok: Callable[[], None] | None = None) -> Call:
        """Send and wait; ``on_ok`` runs on the I/O thread right at the OK Ack, in order.

        A blocking call waits on the Call itself, not on a future: the event
        thread may be busy in a callback (or be the caller), and the bound
        stays :meth:`Rpc.wait`'s.
        """
        call = self._start(msg, on_ok)
        self._rpc.wait(call)
        return call

    def _start(self, msg: ArduinoIn, on_ok: Callable[[], None] | None = None) -> Call:
        """Submit for a blocking call: never from the I/O thread, which alone reads Acks."""
        if self._transport.on_io_thread():
            raise ReentrantCallError(
                f"{msg.WhichOneof('data')} called on the board's I/O thread (from a frame "
                "monitor?): it would wait for an Ack that only this thread can read. Call it "
                "from another thread, or use its submit form (never wait on the future there)"
            )
        return self._submit(msg, on_ok)

    def _future(
        self, msg: ArduinoIn, on_ok: Callable[[], None] | None, value: Callable[[Call], T]
    ) -> Future[T]:
        """Send without waiting; the future gets ``value(call)`` or the call's error.

        It is resolved as the call completes (on the I/O thread, after ``on_ok``, in
        Ack order), or on the event thread if it has done-callbacks
        (:class:`~protoduino.events.EventThreadFuture`). The request layer fails
        every call by its deadline, so every future is resolved, at the latest with
        the blocking call's timeout error, or with BoardClosedError at :meth:`close`.
        """
        future: EventThreadFuture[T] = EventThreadFuture(self._events.put_job)
        future.set_running_or_notify_cancel()  # sent is sent: cancel() says False

        def then(call: Call) -> None:
            future.settle(lambda: value(call))

        self._submit(msg, on_ok, then)
        return future

    def _submit(
        self,
        msg: ArduinoIn,
        on_ok: Callable[[], None] | None,
        then: Callable[[Call], None] | None = None,
    ) -> Call:
        def done(call: Call) -> None:
            if call.error is None and on_ok is not None:
                with self._lock:
                    on_ok()
            if then is not None:
                then(call)

        return self._rpc.submit(msg, on_done=done)

    def _set_output(self, pin: int, state: PinRecord) -> None:
        self._outputs[pin] = state  # an Init drives the safe value: no value to restore

    def _set_value(self, pin: int, control: bytes, value: int) -> None:
        out = self._outputs.get(pin)
        if out is not None:
            out.last = control
            out.value = value

    def _forget_values(self) -> None:
        for out in self._outputs.values():
            out.last = None
            out.value = out.safe

    def _value(self, pin: int, mode: PinMode) -> int | None:
        with self._lock:
            out = self._outputs.get(pin)
            return out.value if out is not None and out.mode is mode else None

    def _failsafe_config(self) -> ArduinoIn:
        msg = ArduinoIn()
        msg.configure_failsafe.timeout_ms = round(self.failsafe_timeout * 1000)  # whole ms
        msg.configure_failsafe.liveness = (
            pb.LIVENESS_HEARTBEAT if self.liveness == "heartbeat" else pb.LIVENESS_PING
        )
        return msg

    def _restore_messages(self) -> list[ArduinoIn]:
        """The failsafe configuration, every Init, then with ``restore="last"`` every
        last value (called on the I/O thread when the device lost the outputs).

        Called with the request layer's lock held, and takes this board's: the one lock
        order (rpc.py, "Lock order"), so nothing here may call into the request layer
        while holding ``self._lock``."""
        lapsed = self._rpc.liveness_lapsed()
        with self._lock:
            outputs = list(self._outputs.values())
            # The device lost its state: a failsafe it reports now is a new one.
            self._failsafe_active, self._failsafe_epoch = False, None
            if self.restore != "last":
                self._forget_values()  # they come up at their safe values
            elif lapsed and any(o.last is not None for o in outputs):
                # No liveness message was acknowledged within the timeout: the device
                # may have gone safe unheard before it lost the outputs, and a restore
                # never undoes a safe state (issue 20, item 2).
                log.warning(
                    "%s: no liveness acknowledged within the failsafe timeout before the "
                    "outputs were lost: restoring safe values only",
                    self.url,
                )
                self._forget_values()
        blobs = [o.init for o in outputs]
        if self.restore == "last":
            blobs += [o.last for o in outputs if o.last is not None]
        msgs = [self._failsafe_config()]
        for blob in blobs:
            msg = ArduinoIn()
            msg.ParseFromString(blob)
            msgs.append(msg)
        return msgs

    def _get_info(self) -> DeviceInfo:
        msg = ArduinoIn()
        msg.get_info.SetInParent()
        return decode_device_info(self._send(msg).result().info)

    def _message(self, msg: ArduinoOut) -> None:
        """A DATA message other than an Ack (I/O thread)."""
        kind = msg.WhichOneof("data")
        if kind == "input_report":
            try:
                self._inputs.update(msg.input_report)
            except ProtocolError as error:
                log.warning("%s: input report dropped: %s", self.url, error)
        elif kind == "user_report":
            report = msg.user_report
            self.user_reports.update(report.report, bytes(report.body), report.coalesced)
        elif kind == "failsafe":
            self._failsafe_state(msg.failsafe)
        elif kind == "decode_error":
            count = msg.decode_error.count
            self._notify(
                Event(
                    EventKind.DECODE_ERROR,
                    "the device could not decode a command",
                    {"count": count},
                )
            )
        else:
            log.info("%s: unhandled device message %s", self.url, kind)

    def _failsafe_state(self, fs: Any) -> None:
        """The device's failsafe state, from its event or a liveness Ack (I/O thread).

        Reported on change only: a safe state once per epoch (whichever of its
        event and a Ping's Ack told first; an Ack tells of one whose event was
        lost), and its clearing once.
        """
        # The wire names one timeout cause, whatever the liveness source: the host
        # names it for what expired (with liveness="heartbeat" no Ping could stop it).
        cause = failsafe_cause(fs.cause)
        if cause == "ping_timeout" and self.liveness == "heartbeat":
            cause = "heartbeat_timeout"
        with self._lock:
            if fs.active:
                if self._failsafe_active and self._failsafe_epoch == fs.epoch:
                    return
                self._forget_values()
            elif not self._failsafe_active:
                self._failsafe_epoch = fs.epoch
                return
            self._failsafe_active, self._failsafe_epoch = fs.active, fs.epoch
        details: dict[str, Any] = {"active": fs.active, "cause": cause, "epoch": fs.epoch}
        if fs.active:
            why = cause
            if cause == "interlock":  # the input that tripped
                details["pin"] = fs.pin
                why = f"interlock on pin {fs.pin}"
            text = f"failsafe active ({why}): outputs at their safe values"
        else:
            text = "failsafe cleared (outputs stay safe until commanded)"
            details["cause"] = "none"
        self._notify(Event(EventKind.FAILSAFE, text, details))

    def _capture_lost(self, error: OSError) -> None:
        """The capture stopped on a write error (whatever thread wrote): said once."""
        assert self._capture is not None
        reason = error.strerror or str(error)
        self._notify(
            Event(
                EventKind.CAPTURE_LOST,
                f"the capture {self._capture.path} stopped: {reason}; the board goes on without it",
                {"path": self._capture.path, "error": reason, "errno": error.errno},
            )
        )

    def _notify(self, event: Event) -> None:
        log.debug("%s: event %s", self.url, event)
        if self._capture is not None:
            self._capture.event(event)
        self._events.put(event)
