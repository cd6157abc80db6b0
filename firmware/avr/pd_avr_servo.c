/*
 * Servo pulses the way the Arduino Servo library makes them: Timer1 runs free
 * at 0.5 us per tick (prescaler 8) and its compare-A interrupt ends one
 * channel's pulse and starts the next one's, channel after channel, then waits
 * out the rest of a 20 ms frame. Not hardware PWM: that serves only pins 9
 * and 10, and simavr does not reflect OCR1A rewrites in PWM mode 14.
 *
 * The Mega runs 12 channels on each of two 16-bit timers, as the Servo library does:
 * channels 0 .. 11 on Timer1, 12 .. 23 on Timer5 (SERVO_TIMERS), each timer with its
 * own sequence and frame (SERVO_TIMER_OF). Timer1 first: its PWM pins within the build's
 * are two (11, 12; its third output, 13, is also Timer0's, the clock's), Timer5's none
 * (44 .. 46), so Timers 3 and 4 stay free for PWM (2, 3, 5 .. 8) however many servos
 * run (firmware/README.md, The Mega 2560). A 12-channel frame outlasts 20 ms once its
 * widths add up to more (the next starts at once then, as the Servo library's does).
 *
 * Every compare time is computed from the previous compare time, never from
 * the counter's current value, so interrupt latency shifts both edges of a
 * pulse alike and drops out of its width; it adds jitter only when another
 * interrupt (UART, clock) delays one edge.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <stdbool.h>
#include <stddef.h>
#include <util/atomic.h>

#include "pd_avr.h"
#include "pd_avr_pins.h"
#include "pd_outputs.h"

#define TICKS_PER_US 2u         /* 16 MHz / 8 */
#define FRAME_TICKS 40000u      /* 20 ms */
/* 40 us (640 cycles): the soonest the next compare may be set, beyond what the ISR's
 * part with interrupts on takes with every other handler nested in it. */
#define MIN_GAP_TICKS 80u
/* The ISR makes an end edge 10 cycles before a start edge (-O s code,
 * avr-gcc 5.4): one tick (8 cycles) gives most of it back. */
#define PULSE_TRIM_TICKS 1u
/* An expedited frame starts a whole number of these (1 ms) after the current
 * frame's start. The clock interrupt (Timer0's overflow, every 1,024 us: the
 * timer also does PWM on pins 5 and 6) has no fixed phase to the frames; its
 * handler turns interrupts back on at its first instruction, so an edge waits
 * for it only its entry (a few cycles). */
#define CLOCK_TICKS 2000u

/* The timers making pulses, and the channels each runs: the Uno's one, Timer1, all of
 * them; the Mega's Timer1 the first 12, Timer5 the next. */
#if PD_BOARD_MEGA
#define SERVO_TIMERS 2u
#define CHANNELS_PER_TIMER 12u
#else
#define SERVO_TIMERS 1u
#define CHANNELS_PER_TIMER PD_MAX_SERVOS
#endif
typedef char pd_assert_servo_timers[(SERVO_TIMERS * CHANNELS_PER_TIMER == PD_MAX_SERVOS) ? 1 : -1];

typedef struct servo_channel {
    volatile uint8_t *port; /* NULL: channel never used (not in the sequence) */
    uint8_t mask;           /* 0: detached (no edges) */
    uint16_t ticks; /* the width this frame's pulse has */
    uint16_t next;  /* the width written, taken into `ticks` at the next frame start */
} servo_channel_t;

/*
 * The channels. tools/avrsim reads this table from the MCU's RAM (by its symbol) to know
 * which pins carry a servo, for its trace: keep its name, and the port and the mask as
 * the first three bytes of a 7-byte entry (asserted below), or change the runner with it.
 */
static servo_channel_t pd_avr_servos[PD_MAX_SERVOS];
typedef char pd_assert_servo_layout[offsetof(servo_channel_t, mask) == 2u &&
                                            sizeof(servo_channel_t) == 7u ? 1 : -1];
/*
 * A timer's sequence. The edges its next compare makes, prepared by the previous
 * one: with no edge to make they point at `no_pin`, so that the ISR runs the same
 * instructions every time: no branch shifts one edge against another.
 */
static volatile uint8_t no_pin;
typedef struct servo_timer {
    volatile uint8_t *off_port; /* pulse to end */
    uint8_t off_mask;
    volatile uint8_t *on_port; /* pulse to start */
    uint8_t on_mask;
    int8_t on_channel;      /* the channel on_port belongs to, -1: none */
    bool in_gap;            /* the next compare ends the gap between frames */
    uint16_t frame_start;   /* compare time at which the current frame began */
} servo_timer_t;
#define SERVO_TIMER_INIT {&no_pin, 0, &no_pin, 0, -1, true, 0}
static servo_timer_t servo_timers[SERVO_TIMERS] = {
    SERVO_TIMER_INIT,
#if SERVO_TIMERS > 1
    SERVO_TIMER_INIT,
#endif
};
/* Start a timer's next frame right after this one (zero at power-up: in .bss). */
static volatile bool expedite[SERVO_TIMERS];
/* Channel `ch`'s timer (an index of servo_timers), and a timer's first channel and the one
 * after its last. */
#define SERVO_TIMER_OF(ch) (SERVO_TIMERS == 1 ? 0u : (uint8_t)((ch) / CHANNELS_PER_TIMER))
#define FIRST_CHANNEL(t) ((uint8_t)((t) * CHANNELS_PER_TIMER))
#define END_CHANNEL(t) ((uint8_t)(((t) + 1u) * CHANNELS_PER_TIMER))

/* A timer's registers: folded into constant addresses wherever `t` is a constant (every
 * interrupt's, and the loops over the timers, which the compiler unrolls). */
static inline __attribute__((always_inline)) volatile uint16_t *timer_ocr(uint8_t t)
{
#if SERVO_TIMERS > 1
    if (t == 1) {
        return &OCR5A;
    }
#endif
    (void)t;
    return &OCR1A;
}
static inline __attribute__((always_inline)) volatile uint16_t *timer_tcnt(uint8_t t)
{
#if SERVO_TIMERS > 1
    if (t == 1) {
        return &TCNT5;
    }
#endif
    (void)t;
    return &TCNT1;
}
static inline __attribute__((always_inline)) volatile uint8_t *timer_timsk(uint8_t t)
{
#if SERVO_TIMERS > 1
    if (t == 1) {
        return &TIMSK5;
    }
#endif
    (void)t;
    return &TIMSK1;
}
/* OCIEnA, OCFnA and CSn1 are the same bits on every 16-bit timer. */
typedef char pd_assert_timer_bits[(OCIE1A == 1 && OCF1A == 1 && CS11 == 1) ? 1 : -1];
/* Writes are held (pd_avr_servo_hold): frame starts leave `next` alone. */
static volatile bool held;
/* Not 0: a width written to one of timer t's channels waits for its frame start
 * (pd_avr_servo_pending). A byte a timer, each written whole: no read-modify-write that
 * the Mega's other timer's compare, nesting, could cut in two. */
static volatile uint8_t unlatched[SERVO_TIMERS];

/*
 * The soonest frame start after `now`: frame_start plus a whole number of
 * CLOCK_TICKS, at least MIN_GAP_TICKS away. Used when a safe state must reach the pins at once.
 */
static uint16_t soonest_start(uint16_t frame_start, uint16_t now)
{
    /* The whole CLOCK_TICKS in `elapsed` (under 32 of them: a frame and a bit), taken away
     * 16, 8, 4, 2 and 1 at a time: five rounds, where counting them one by one took up to
     * 33 (no 16-bit division on the AVR), with interrupts off in pd_avr_servo_expedite. */
    uint16_t elapsed = (uint16_t)(now + MIN_GAP_TICKS - frame_start);
    uint16_t rest = elapsed;
    for (uint16_t step = 16u * CLOCK_TICKS; step >= CLOCK_TICKS; step >>= 1) {
        if (rest >= step) {
            rest = (uint16_t)(rest - step);
        }
    }
    return (uint16_t)(frame_start + (elapsed - rest) + CLOCK_TICKS);
}

#if SERVO_TIMERS > 1
/*
 * Timer5's frames, started when the first of its channels joins the sequence (and not at
 * power-up: an empty frame's compare still holds interrupts off for its edges, about 80
 * cycles every 20 ms that a Timer1 edge met now and then). They start half a clock tick
 * off Timer1's frame starts: the two timers' first edges, which the frame starts make at
 * once, do not fall together (one interrupt would hold the other's edge off), nor do they
 * after an expedited frame, which keeps each timer's phase to its clock ticks
 * (soonest_start). Worked out with interrupts on, between two short atomic reads and
 * writes; the time that takes is well inside MIN_GAP_TICKS.
 */
static void timer5_start(void)
{
    uint16_t now;
    uint16_t phase; /* a Timer1 frame start, on Timer5's count, half a tick back */
    bool aligned;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        now = TCNT5;
        phase = (uint16_t)(servo_timers[0].frame_start + (uint16_t)(now - TCNT1) -
                           CLOCK_TICKS / 2u);
        aligned = (TIMSK1 & _BV(OCIE1A)) != 0; /* Timer1 makes frames (not PWM) */
    }
    uint16_t first = aligned ? soonest_start(phase, now) : (uint16_t)(now + MIN_GAP_TICKS);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        servo_timers[1].in_gap = true;
        OCR5A = first;
        TIFR5 = _BV(OCF5A);
        TIMSK5 |= _BV(OCIE5A);
    }
}
#endif

void pd_avr_servo_init(void)
{
    TCCR1A = 0; /* normal mode: the counter runs free over 16 bits */
    TCCR1B = _BV(CS11);
    OCR1A = (uint16_t)(TCNT1 + FRAME_TICKS);
    TIFR1 = _BV(OCF1A);
    TIMSK1 |= _BV(OCIE1A);
#if SERVO_TIMERS > 1
    /* Timer5 counts from here, in step with Timer1 (one prescaler), but its frames run
     * only once one of its channels is in the sequence (timer5_start). */
    TCCR5A = 0;
    TCCR5B = _BV(CS51);
    TIMSK5 &= (uint8_t)~_BV(OCIE5A);
    for (uint8_t ch = FIRST_CHANNEL(1); ch < END_CHANNEL(1); ch++) {
        if (pd_avr_servos[ch].port != NULL) {
            timer5_start();
            break;
        }
    }
#endif
}

/* The first channel from `ch` to `end` (exclusive) in the sequence, or -1. */
static int8_t next_attached(int8_t ch, uint8_t end)
{
    while (ch < (int8_t)end && pd_avr_servos[ch].port == NULL) {
        ch++;
    }
    return ch < (int8_t)end ? ch : -1;
}

/*
 * Only the edges are made with interrupts off; the rest (the next compare time, a
 * frame's new widths, the next edges' ports) runs with them on and this interrupt
 * masked, so that it cannot nest. The counters' INT0 and INT1 wait behind this handler
 * alone: all of it held them off for up to 290 cycles, and behind a UART handler's
 * first instructions and the other counter's that came to more than the 400 cycles
 * between edges at 40,000 a second, now and then (issue 32: tools/avrsim --stats
 * "extint", firmware/README.md). On the Mega the other servo timer's edges wait
 * behind it too: with the next compare time made before `sei` as well, that was
 * about 130 cycles, 8 us off a pulse when the two timers' compares met. MIN_GAP_TICKS
 * keeps the soonest compare it sets further away than the rest takes, nested
 * interrupts included.
 */
/* Timer `t`'s compare (a constant: each interrupt has its own copy, its registers and
 * its state at fixed addresses). */
static inline __attribute__((always_inline)) void servo_compare(uint8_t t)
{
    servo_timer_t *tm = &servo_timers[t];
    volatile uint16_t *ocr = timer_ocr(t);
    uint16_t at = *ocr; /* when this compare was due */

    /* The edges come first, at the same short offset after every compare,
     * so that a pulse's two edges are equally late and its width exact. */
    *tm->off_port &= (uint8_t)~tm->off_mask;
    *tm->on_port |= tm->on_mask;
    /* The rest with interrupts on: the other timer's edges (the Mega's) and the counters'
     * interrupts wait only for the edges above. This handler cannot nest in itself, and
     * the main loop, the only other writer of this timer's state, cannot run before it
     * returns; the compare time it sets below is at least MIN_GAP_TICKS away, further
     * than any nesting takes. */
    *timer_timsk(t) &= (uint8_t)~_BV(OCIE1A);
    sei();

    bool starts = tm->in_gap; /* this compare starts a frame */
    if (starts) {
        tm->frame_start = at;
        tm->in_gap = false;
    }
    /* Every new width starts at a frame start, so that widths written together (a
     * Pose, a speed step) reach the pins in the same frame: the first channel's is
     * the one written, and the others' are taken below, long before their turn. */
    bool take = starts && !held;
    if (take) {
        unlatched[t] = 0;
    }
    int8_t ch = tm->on_channel; /* the channel now high, if any */
    if (ch >= 0) {
        /* The end edge is made a few cycles before the start edge in the
         * ISR: PULSE_TRIM_TICKS gives them back. */
        uint16_t ticks = take ? pd_avr_servos[ch].next : pd_avr_servos[ch].ticks;
        *ocr = (uint16_t)(at + ticks + PULSE_TRIM_TICKS);
    } else {
        /* End of the frame: wait out its 20 ms, or start the next at once when
         * eight 2.6 ms pulses have outlasted it. */
        if ((uint16_t)(at - tm->frame_start) > FRAME_TICKS - MIN_GAP_TICKS) {
            *ocr = (uint16_t)(*timer_tcnt(t) + MIN_GAP_TICKS);
        } else if (expedite[t]) {
            *ocr = soonest_start(tm->frame_start, *timer_tcnt(t));
        } else {
            *ocr = (uint16_t)(tm->frame_start + FRAME_TICKS);
        }
        expedite[t] = false;
        tm->in_gap = true;
    }

    if (take) {
        for (uint8_t n = FIRST_CHANNEL(t); n < END_CHANNEL(t); n++) {
            pd_avr_servos[n].ticks = pd_avr_servos[n].next;
        }
    }
    if (ch >= 0) {
        tm->off_port = pd_avr_servos[ch].port;
        tm->off_mask = pd_avr_servos[ch].mask;
        ch = next_attached((int8_t)(ch + 1), END_CHANNEL(t));
    } else {
        tm->off_port = &no_pin;
        ch = next_attached((int8_t)FIRST_CHANNEL(t), END_CHANNEL(t));
    }
    tm->on_channel = ch;
    if (ch >= 0) {
        tm->on_port = pd_avr_servos[ch].port;
        tm->on_mask = pd_avr_servos[ch].mask;
    } else {
        tm->on_port = &no_pin;
    }
    cli();
    *timer_timsk(t) |= _BV(OCIE1A);
}

ISR(TIMER1_COMPA_vect)
{
    servo_compare(0);
}

#if SERVO_TIMERS > 1
ISR(TIMER5_COMPA_vect)
{
    servo_compare(1);
}
#endif

/* A pin's PORT register and bit, not inlined: servo writes and digital pins
 * share one copy of the lookup. */
static __attribute__((noinline)) volatile uint8_t *pin_port(uint8_t pin, uint8_t *mask)
{
    return pd_avr_port(pin, mask);
}

/*
 * Everything that can be is worked out before interrupts go off: they stay off only for
 * the stores, because a servo edge waits for them (the Mega's channel/12, a division,
 * inside the block held them off for 135 cycles, 8 us off a pulse: test_board_sim's
 * concurrent callers on the emulated Mega, tools/avrsim's trace).
 */
void pd_avr_servo_write(uint8_t channel, uint8_t pin, uint16_t us)
{
    if (channel >= PD_MAX_SERVOS) {
        return;
    }
    uint16_t ticks = (uint16_t)(us * TICKS_PER_US);
    uint8_t mask;
    volatile uint8_t *port = pin_port(pin, &mask);
    uint8_t t = SERVO_TIMER_OF(channel);
    servo_channel_t *c = &pd_avr_servos[channel];
    const servo_timer_t *tm = &servo_timers[t];
    /* Opaque from here: the compiler would otherwise work the addresses out again (a
     * multiply each) inside the block, where they cost interrupts-off time. */
    __asm__("" : "+r"(c), "+r"(tm));
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        if (c->port != port || c->mask != mask) {
            /* Attach (first use, after a detach, or another pin): output, low,
             * joins the sequence at the channel's next turn. A pulse still under
             * way on this pin (detached a moment ago) ends by its own edge. */
            c->mask = mask; /* first: the table says servo when the pin turns output */
            c->port = port;
            c->ticks = ticks; /* valid for the next frame, held or not */
            if (tm->off_port != port || !(tm->off_mask & mask)) {
                *port &= (uint8_t)~mask;
            }
            *pd_avr_ddr(port) |= mask;
        }
        c->next = ticks;
        unlatched[t] = 1;
    }
#if SERVO_TIMERS > 1
    if (t == 1 && !(TIMSK5 & _BV(OCIE5A)) && !(TCCR5A & _BV(WGM50))) {
        timer5_start(); /* its first channel (and not PWM's: pd_avr_pwm.c) */
    }
#endif
}

void pd_avr_servo_hold(bool hold)
{
    held = hold;
}

bool pd_avr_servo_pending(void)
{
#if SERVO_TIMERS > 1
    return (unlatched[0] | unlatched[1]) != 0;
#else
    return unlatched[0] != 0;
#endif
}

/*
 * The channel keeps its place in the frame with no edges (mask 0), so the
 * frame's timing does not move; the pin is left alone: a pulse under way ends
 * at its own time through the off edge the ISR already holds, and a pulse
 * about to start is cancelled before it does.
 */
void pd_avr_servo_detach(uint8_t channel)
{
    if (channel >= PD_MAX_SERVOS) {
        return;
    }
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        pd_avr_servos[channel].mask = 0;
        servo_timer_t *tm = &servo_timers[SERVO_TIMER_OF(channel)];
        if (tm->on_channel == (int8_t)channel) {
            tm->on_mask = 0;
        }
    }
}

void pd_avr_servo_expedite(void)
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        for (uint8_t t = 0; t < SERVO_TIMERS; t++) {
            servo_timer_t *tm = &servo_timers[t];
            if (!(*timer_timsk(t) & _BV(OCIE1A))) {
                /* The timer runs PWM (pd_avr_pwm.c took it over): its OCRnA is a duty,
                 * never a frame time (written there, the PWM pin showed duty 255 at a
                 * failsafe instead of its safe duty). Or it makes no frames yet (the
                 * Mega's Timer5 before its first channel: timer5_start). */
                continue;
            }
            if (!tm->in_gap) {
                /* Pulses under way: the frame's end starts the next one early. */
                expedite[t] = true;
            } else {
                /* Waiting out the frame: cut the wait short if that is sooner. */
                uint16_t now = *timer_tcnt(t);
                uint16_t start = soonest_start(tm->frame_start, now);
                if ((uint16_t)(start - now) < (uint16_t)(*timer_ocr(t) - now)) {
                    *timer_ocr(t) = start;
                }
            }
        }
    }
}

/* One function for both (the pin lookups cost flash each time they are inlined). */
void pd_avr_pin_set(uint8_t pin, bool output, bool level)
{
    uint8_t mask;
    volatile uint8_t *port = pin_port(pin, &mask);
    volatile uint8_t *ddr = pd_avr_ddr(port);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        if (!output) {
            *ddr &= (uint8_t)~mask; /* input first: the pin never drives the other level */
        }
        if (level) {
            *port |= mask;
        } else {
            *port &= (uint8_t)~mask;
        }
        if (output) {
            *ddr |= mask;
        }
    }
}
