/*
 * Servo pulses the way the Arduino Servo library makes them: Timer1 runs free
 * at 0.5 us per tick (prescaler 8) and its compare-A interrupt ends one
 * channel's pulse and starts the next one's, channel after channel, then waits
 * out the rest of a 20 ms frame. Not hardware PWM: that serves only pins 9
 * and 10, and simavr does not reflect OCR1A rewrites in PWM mode 14.
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
 * The edges the next compare makes, prepared by the previous one. With no
 * edge to make they point at `no_pin`, so that the ISR runs the same
 * instructions every time: no branch shifts one edge against another.
 */
static volatile uint8_t no_pin;
static volatile uint8_t *off_port = &no_pin; /* pulse to end */
static uint8_t off_mask;
static volatile uint8_t *on_port = &no_pin; /* pulse to start */
static uint8_t on_mask;
static int8_t on_channel = -1; /* the channel on_port belongs to, -1: none */
static bool in_gap = true;     /* the next compare ends the gap between frames */
static uint16_t frame_start;   /* compare time at which the current frame began */
static volatile bool expedite; /* start the next frame right after this one */
/* Writes are held (pd_avr_servo_hold): frame starts leave `next` alone. */
static volatile bool held;

/*
 * The soonest frame start after `now`: frame_start plus a whole number of
 * CLOCK_TICKS, at least MIN_GAP_TICKS away. Used when a safe state must reach the pins at once.
 */
static uint16_t soonest_start(uint16_t now)
{
    uint16_t elapsed = (uint16_t)(now + MIN_GAP_TICKS - frame_start);
    uint16_t offset = CLOCK_TICKS;
    while (offset <= elapsed) { /* at most 33 rounds; no 16-bit division on the AVR */
        offset += CLOCK_TICKS;
    }
    return (uint16_t)(frame_start + offset);
}

void pd_avr_servo_init(void)
{
    TCCR1A = 0; /* normal mode: the counter runs free over 16 bits */
    TCCR1B = _BV(CS11);
    OCR1A = (uint16_t)(TCNT1 + FRAME_TICKS);
    TIFR1 = _BV(OCF1A);
    TIMSK1 |= _BV(OCIE1A);
}

static int8_t next_attached(int8_t ch)
{
    while (ch < (int8_t)PD_MAX_SERVOS && pd_avr_servos[ch].port == NULL) {
        ch++;
    }
    return ch < (int8_t)PD_MAX_SERVOS ? ch : -1;
}

/*
 * Only the edges and the next compare time are made with interrupts off; the rest (a
 * frame's new widths, the next edges' ports) runs with them on and this interrupt
 * masked, so that it cannot nest. The counters' INT0 and INT1 wait behind this handler
 * alone: all of it held them off for up to 290 cycles, and behind a UART handler's
 * first instructions and the other counter's that came to more than the 400 cycles
 * between edges at 40,000 a second, now and then (issue 32: tools/avrsim --stats
 * "extint", firmware/README.md). MIN_GAP_TICKS keeps the soonest compare it sets
 * further away than the rest takes, nested interrupts included.
 */
ISR(TIMER1_COMPA_vect)
{
    uint16_t at = OCR1A; /* when this compare was due */

    /* The edges come first, at the same short offset after every compare,
     * so that a pulse's two edges are equally late and its width exact. */
    *off_port &= (uint8_t)~off_mask;
    *on_port |= on_mask;

    bool starts = in_gap; /* this compare starts a frame */
    if (starts) {
        frame_start = at;
        in_gap = false;
    }
    /* Every new width starts at a frame start, so that widths written together (a
     * Pose, a speed step) reach the pins in the same frame: the first channel's is
     * the one written, and the others' are taken below, long before their turn. */
    bool take = starts && !held;
    int8_t ch = on_channel; /* the channel now high, if any */
    if (ch >= 0) {
        /* The end edge is made a few cycles before the start edge in the
         * ISR: PULSE_TRIM_TICKS gives them back. */
        uint16_t ticks = take ? pd_avr_servos[ch].next : pd_avr_servos[ch].ticks;
        OCR1A = (uint16_t)(at + ticks + PULSE_TRIM_TICKS);
    } else {
        /* End of the frame: wait out its 20 ms, or start the next at once when
         * eight 2.6 ms pulses have outlasted it. */
        if ((uint16_t)(at - frame_start) > FRAME_TICKS - MIN_GAP_TICKS) {
            OCR1A = (uint16_t)(TCNT1 + MIN_GAP_TICKS);
        } else if (expedite) {
            OCR1A = soonest_start(TCNT1);
        } else {
            OCR1A = (uint16_t)(frame_start + FRAME_TICKS);
        }
        expedite = false;
        in_gap = true;
    }
    TIMSK1 &= (uint8_t)~_BV(OCIE1A);
    sei();

    if (take) {
        for (uint8_t n = 0; n < PD_MAX_SERVOS; n++) {
            pd_avr_servos[n].ticks = pd_avr_servos[n].next;
        }
    }
    if (ch >= 0) {
        off_port = pd_avr_servos[ch].port;
        off_mask = pd_avr_servos[ch].mask;
        ch = next_attached((int8_t)(ch + 1));
    } else {
        off_port = &no_pin;
        ch = next_attached(0);
    }
    on_channel = ch;
    if (ch >= 0) {
        on_port = pd_avr_servos[ch].port;
        on_mask = pd_avr_servos[ch].mask;
    } else {
        on_port = &no_pin;
    }
    cli();
    TIMSK1 |= _BV(OCIE1A);
}

/* A pin's PORT register and bit, not inlined: servo writes and digital pins
 * share one copy of the lookup. */
static __attribute__((noinline)) volatile uint8_t *pin_port(uint8_t pin, uint8_t *mask)
{
    return pd_avr_port(pin, mask);
}

void pd_avr_servo_write(uint8_t channel, uint8_t pin, uint16_t us)
{
    if (channel >= PD_MAX_SERVOS) {
        return;
    }
    uint16_t ticks = (uint16_t)(us * TICKS_PER_US);
    uint8_t mask;
    volatile uint8_t *port = pin_port(pin, &mask);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        servo_channel_t *c = &pd_avr_servos[channel];
        if (c->port != port || c->mask != mask) {
            /* Attach (first use, after a detach, or another pin): output, low,
             * joins the sequence at the channel's next turn. A pulse still under
             * way on this pin (detached a moment ago) ends by its own edge. */
            c->mask = mask; /* first: the table says servo when the pin turns output */
            c->port = port;
            c->ticks = ticks; /* valid for the next frame, held or not */
            if (off_port != port || !(off_mask & mask)) {
                *port &= (uint8_t)~mask;
            }
            *pd_avr_ddr(port) |= mask;
        }
        c->next = ticks;
    }
}

void pd_avr_servo_hold(bool hold)
{
    held = hold;
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
        if (on_channel == (int8_t)channel) {
            on_mask = 0;
        }
    }
}

void pd_avr_servo_expedite(void)
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        if (!in_gap) {
            /* Pulses under way: the frame's end starts the next one early. */
            expedite = true;
        } else {
            /* Waiting out the frame: cut the wait short if that is sooner. */
            uint16_t now = TCNT1;
            uint16_t start = soonest_start(now);
            if ((uint16_t)(start - now) < (uint16_t)(OCR1A - now)) {
                OCR1A = start;
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
