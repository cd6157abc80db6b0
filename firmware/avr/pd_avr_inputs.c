/*
 * Inputs on the Uno (pd_hal.h, pd_inputs.c).
 *
 * - Digital inputs read PINx. A configured input also wakes the main loop on
 *   every change (its pin-change interrupt): the loop sleeps between
 *   interrupts, and without this an input's edge would wait for the next 1 ms
 *   clock tick to be seen. An interlock reacts within one pass of the loop
 *   (tens of microseconds), not within a millisecond.
 * - Analog inputs: one conversion at a time, never waited for; the ADC's
 *   interrupt wakes the loop when it is done, so conversions follow each other
 *   at the ADC's pace (13 ADC clocks at 125 kHz: 104 us) rather than the clock
 *   tick's. AVCC reference, 10 bits.
 * Both interrupts only make a pass due with news for its poll (PD_AVR_PASS,
 * both bits): an interrupt that lands after the loop's pass has read the
 * inputs but before it sleeps must still keep it awake for one more pass
 * (pd_avr_loop checks the bit with interrupts off), or the change would wait
 * for the next clock tick after all.
 * - Counters: INT0 (pin 2) and INT1 (pin 3), each edge counted in its
 *   interrupt (rising, falling or both, chosen in EICRA); pins 4..13 in their
 *   port's pin-change interrupt, which compares the pin with its last level.
 *   What rate loses no edge is measured (docs/protocol.md, Counters): an edge
 *   is lost only when two come (a pin changes twice) before the handler has
 *   run once.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <stdbool.h>
#include <util/atomic.h>

#include "pd_avr.h"
#include "pd_avr_pins.h"
#include "pd_features.h"
#include "pd_hal.h"

/* Counters on pin-change interrupts: the Uno's ports B, C and D (pins 4..13). The
 * Mega counts on its six external interrupts only (its pin changes are on other ports). */
#define PD_AVR_PC_COUNTERS (PD_FEATURE_COUNTER && !PD_BOARD_MEGA)

#if PD_FEATURE_DIGITAL_INPUT || PD_FEATURE_ANALOG_INPUT || PD_FEATURE_COUNTER

/* An analog pin's digital input disable register (its bit: the channel's of eight): DIDR0 for
 * A0..A7, and on the Mega DIDR2 for A8..A15 (pins 62..69). */
static volatile uint8_t *pd_avr_didr(uint8_t pin)
{
#if PD_BOARD_MEGA
    if (pin >= PD_AVR_FIRST_ANALOG + 8u) {
        return &DIDR2;
    }
#endif
    (void)pin;
    return &DIDR0;
}

/* The pin's pin-change mask register and its bit there (PCINT0..23 follow the ports). */
static volatile uint8_t *pcmsk(uint8_t pin, uint8_t *bit, uint8_t *group)
{
    volatile uint8_t *port = pd_avr_port(pin, bit);
#if PD_BOARD_MEGA
    /* The Mega's pin changes: port B (PCINT0..7: pins 10-13, 50-53) and K (PCINT16..23:
     * A8-A15); of the rest only PE0 and PJ0..6 (PCINT8..15, pins 0, 15, 14), and pin 0
     * is the link. A pin without one is read at the next 1 ms clock tick: no wake-up. */
    if (port == &PORTJ) {
        *bit = (uint8_t)(*bit << 1);
        *group = _BV(PCIE1);
        return &PCMSK1;
    }
    if (port == &PORTK) {
        *group = _BV(PCIE2);
        return &PCMSK2;
    }
    if (port != &PORTB) {
        static uint8_t none; /* a mask no interrupt reads */
        *group = 0;
        return &none;
    }
#endif
    if (port == &PORTB) {
        *group = _BV(PCIE0);
        return &PCMSK0;
    }
    if (port == &PORTC) {
        *group = _BV(PCIE1);
        return &PCMSK1;
    }
    *group = _BV(PCIE2);
    return &PCMSK2;
}

#if PD_AVR_PC_COUNTERS
/* Each port's pins as its pin-change handler last read them (PINB, PINC, PIND), and as
 * pd_avr_input_config read a pin when its interrupt went on. */
static volatile uint8_t pc_last[3];

/* The PINx register of the port whose pin-change mask register is `mask`. */
static volatile uint8_t *pc_pins(const volatile uint8_t *mask)
{
    return mask == &PCMSK0 ? &PINB : mask == &PCMSK1 ? &PINC : &PIND;
}
#endif

void pd_avr_input_config(uint8_t pin, bool pull_up, bool wake)
{
    uint8_t bit;
    uint8_t group;
#if PD_BOARD_NANO
    if (pin >= 20u) {
        return; /* A6, A7: the ADC's inputs only, no port behind them */
    }
#endif
    volatile uint8_t *mask = pcmsk(pin, &bit, &group);
    pd_avr_pin_set(pin, false, pull_up); /* an input; PORT's bit is the pull-up */
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        if (pin >= PD_AVR_FIRST_ANALOG) {
            /* Its digital input buffer back on (an analog input's conversions turn it off). */
            *pd_avr_didr(pin) &= (uint8_t)~bit;
        }
        if (wake) {
            *mask |= bit;
            PCICR |= group;
#if PD_AVR_PC_COUNTERS
            /* The handler wakes the loop for a pin whose level differs from its last
             * reading of the port, which did not see this pin while its interrupt was off:
             * the pin's level now goes into it, or an edge back to the level of that
             * reading would wake nothing (the loop would see it at the next clock tick). */
            uint8_t g = (uint8_t)(group >> 1); /* PCIE0..2 -> 0..2 */
            pc_last[g] = (uint8_t)((pc_last[g] & (uint8_t)~bit) | (*pc_pins(mask) & bit));
#endif
        } else {
            *mask &= (uint8_t)~bit;
        }
    }
}

#if PD_BOARD_MEGA
pd_pinset_t pd_avr_pins_read(void)
{
    /* The Mega's pins are spread over eleven ports: each read at its PIN register (its
     * PORT's address less 2, pd_avr_pins.h). */
    pd_pinset_t levels = {{0}};
    for (uint8_t pin = 0; pin < PD_MAX_PINS; pin++) {
        uint8_t bit;
        volatile uint8_t *port = pd_avr_port(pin, &bit);
        if (*(port - 2) & bit) {
            pd_pinset_put(&levels, pin, true);
        }
    }
    return levels;
}
#else
pd_pinset_t pd_avr_pins_read(void)
{
    /* Uno pins: D0..D7 = PIND, D8..D13 = PINB0..5, A0..A5 (14..19) = PINC0..5. */
    pd_pinset_t levels = {
        {(uint32_t)PIND | (uint32_t)(PINB & 0x3Fu) << 8 | (uint32_t)(PINC & 0x3Fu) << 14}};
    return levels;
}
#endif

/* A pass due with news (two `sbi`): no register, no flag of SREG, no stack but the return
 * address; 4 cycles and the return. */
#define PD_WAKE_ISR(vector)                                                  \
    ISR(vector, ISR_NAKED)                                                   \
    {                                                                        \
        __asm__ volatile("sbi %[pass], %[news]\n\t"                          \
                         "sbi %[pass], %[bit]\n\t"                           \
                         "reti\n\t"                                          \
                         :                                                   \
                         : [pass] "I"(_SFR_IO_ADDR(PD_AVR_PASS)),            \
                           [news] "I"(PD_AVR_NEWS_BIT), [bit] "I"(PD_AVR_PASS_BIT)); \
    }

#if !PD_AVR_PC_COUNTERS /* else the counters' pin-change handlers wake the loop too */
PD_WAKE_ISR(PCINT0_vect)
PD_WAKE_ISR(PCINT1_vect)
PD_WAKE_ISR(PCINT2_vect)
#endif

#endif

#if PD_FEATURE_ANALOG_INPUT

void pd_avr_analog_start(uint8_t pin)
{
#if PD_BOARD_MEGA
    /* A0..A15 (pins 54..69) are ADC0..ADC15: ADMUX's MUX2:0 name the channel of eight, and
     * ADCSRB's MUX5 the upper eight (A8..A15, the datasheet's single-ended 0b100xxx). */
    uint8_t channel = (uint8_t)(pin - PD_AVR_FIRST_ANALOG);
    ADMUX = (uint8_t)(_BV(REFS0) | (channel & 0x07u)); /* AVCC */
    ADCSRB = channel >= 8u ? _BV(MUX5) : 0u;
    *pd_avr_didr(pin) |= (uint8_t)_BV(channel & 0x07u); /* no digital input buffer there */
#else
    ADMUX = (uint8_t)(_BV(REFS0) | ((pin - 14u) & 0x07u)); /* AVCC, channel A0..A5 (A7) */
#if PD_BOARD_NANO
    if (pin < 20u) /* A6, A7 have no digital input buffer (DIDR0's bits 6, 7 are reserved) */
#endif
        DIDR0 |= (uint8_t)_BV((pin - 14u) & 0x07u); /* no digital input buffer there */
#endif
    ADCSRA = _BV(ADEN) | _BV(ADSC) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
}

bool pd_avr_analog_done(uint16_t *counts)
{
    if (ADCSRA & _BV(ADSC)) {
        return false;
    }
    *counts = ADC;
    return true;
}

PD_WAKE_ISR(ADC_vect)

#endif

#if PD_FEATURE_COUNTER

#if PD_AVR_PC_COUNTERS
/* The two counters' counts (the core runs two at most, PD_MAX_COUNTERS): INT0
 * (pin 2) counts into slot 0, INT1 (pin 3) into slot 1, a pin-change counter
 * into a slot neither of them uses. */
volatile uint32_t pd_avr_counts[2];
#else
volatile uint32_t pd_avr_counts[PD_AVR_COUNTERS]; /* per INTn (PD_AVR_INT_OF: pd_avr.h) */
#endif
#define counts pd_avr_counts

#if PD_AVR_PC_COUNTERS
/* A pin-change counter per slot: its pin's bit in its port (0: none), and its
 * mode: the port's group (PCINT0..2 = PORTB, PORTC, PORTD: bits 0-1), the Edge
 * (bits 2-3) and the pin's last level (bit 7). */
static volatile uint8_t pc_mask[2];
static volatile uint8_t pc_mode[2];

/*
 * One counter slot in a pin-change handler (r23: the port's pins now, r22: the
 * port's counting pins, gathered). If slot `s` counts a pin of this group whose
 * level is not its last one: the new level becomes the last, and the edge counts
 * when the counter's Edge asks for it: rising (Edge bit 2 clear) at a high level,
 * falling (set) at a low one, both (bit 3) always. count += 1 as the INT
 * handlers do it. Two changes of the pin before its handler reads the port are
 * not seen (the level is back where it was): the lossless rate is measured
 * (docs/protocol.md, Counters).
 */
#define PD_PC_SLOT(s)                                                                    \
    "lds r25, %[mode" #s "]\n\t"                                                         \
    "mov r24, r25\n\t"                                                                   \
    "andi r24, 3\n\t"                                                                    \
    "cpi r24, %[group]\n\t"                                                              \
    "brne 3f\n\t"                                                                        \
    "lds r24, %[mask" #s "]\n\t"                                                         \
    "tst r24\n\t"                                                                        \
    "breq 3f\n\t"                                                                        \
    "or r22, r24\n\t" /* a counting pin of this port */                                 \
    "and r24, r23\n\t"                                                                   \
    "breq 1f\n\t"                                                                        \
    "ldi r24, 0x80\n\t"                                                                  \
    "1:\n\t"                                                                             \
    "eor r24, r25\n\t"                                                                   \
    "sbrs r24, 7\n\t"                                                                    \
    "rjmp 3f\n\t"                                                                        \
    "subi r25, 0x80\n\t" /* the new level is the last one */                             \
    "sts %[mode" #s "], r25\n\t"                                                         \
    "sbrc r25, 3\n\t"                                                                    \
    "rjmp 2f\n\t"                                                                        \
    "mov r24, r25\n\t"                                                                   \
    "bst r25, 2\n\t"                                                                     \
    "bld r24, 7\n\t"                                                                     \
    "eor r24, r25\n\t"                                                                   \
    "sbrs r24, 7\n\t"                                                                    \
    "rjmp 3f\n\t"                                                                        \
    "2:\n\t"                                                                             \
    "lds r24, %[c" #s "0]\n\t"                                                           \
    "subi r24, 0xFF\n\t"                                                                 \
    "sts %[c" #s "0], r24\n\t"                                                           \
    "lds r24, %[c" #s "1]\n\t"                                                           \
    "sbci r24, 0xFF\n\t"                                                                 \
    "sts %[c" #s "1], r24\n\t"                                                           \
    "lds r24, %[c" #s "2]\n\t"                                                           \
    "sbci r24, 0xFF\n\t"                                                                 \
    "sts %[c" #s "2], r24\n\t"                                                           \
    "lds r24, %[c" #s "3]\n\t"                                                           \
    "sbci r24, 0xFF\n\t"                                                                 \
    "sts %[c" #s "3], r24\n\t"                                                           \
    "3:\n\t"

/*
 * A pin change in group `g` (PCINT0..2: PORTB, PORTC, PORTD), its port read from
 * `pins`: each counter there counts its edge (PD_PC_SLOT), in five registers (7 B
 * of stack where the compiler's handler took 22: every byte of an interrupt's
 * frame can land on the deepest stack, test_stack_margin). A change of a pin
 * that counts nothing (a digital input's: the port's pins against pc_last)
 * wakes the loop; a counter's edge does not (the loop reads counts once per
 * report interval).
 */
#define PD_PC_ISR(vector, g, pins)                                                       \
    ISR(vector, ISR_NAKED)                                                               \
    {                                                                                    \
        __asm__ volatile("push r24\n\t"                                                  \
                         "in r24, __SREG__\n\t"                                          \
                         "push r24\n\t"                                                  \
                         "push r25\n\t"                                                  \
                         "push r23\n\t"                                                  \
                         "push r22\n\t"                                                  \
                         "in r23, %[port]\n\t"                                           \
                         "clr r22\n\t" PD_PC_SLOT(0) PD_PC_SLOT(1)                       \
                         "lds r24, %[last]\n\t"                                          \
                         "sts %[last], r23\n\t"                                          \
                         "eor r24, r23\n\t" /* the port's pins that changed */           \
                         "com r22\n\t"                                                   \
                         "and r24, r22\n\t" /* ... and count nothing */                  \
                         "breq 4f\n\t"                                                   \
                         "sbi %[pass], %[news]\n\t" /* a pass due, with news */          \
                         "sbi %[pass], %[bit]\n\t"                                       \
                         "4:\n\t"                                                        \
                         "pop r22\n\t"                                                   \
                         "pop r23\n\t"                                                   \
                         "pop r25\n\t"                                                   \
                         "pop r24\n\t"                                                   \
                         "out __SREG__, r24\n\t"                                         \
                         "pop r24\n\t"                                                   \
                         "reti\n\t"                                                      \
                         :                                                               \
                         : [port] "I"(_SFR_IO_ADDR(pins)), [group] "M"(g),               \
                           [last] "i"(&pc_last[g]),                                      \
                           [pass] "I"(_SFR_IO_ADDR(PD_AVR_PASS)),                        \
                           [news] "I"(PD_AVR_NEWS_BIT), [bit] "I"(PD_AVR_PASS_BIT),      \
                           [mode0] "i"(&pc_mode[0]),                                     \
                           [mode1] "i"(&pc_mode[1]), [mask0] "i"(&pc_mask[0]),           \
                           [mask1] "i"(&pc_mask[1]),                                     \
                           [c00] "i"((uint8_t *)&counts[0] + 0),                         \
                           [c01] "i"((uint8_t *)&counts[0] + 1),                         \
                           [c02] "i"((uint8_t *)&counts[0] + 2),                         \
                           [c03] "i"((uint8_t *)&counts[0] + 3),                         \
                           [c10] "i"((uint8_t *)&counts[1] + 0),                         \
                           [c11] "i"((uint8_t *)&counts[1] + 1),                         \
                           [c12] "i"((uint8_t *)&counts[1] + 2),                         \
                           [c13] "i"((uint8_t *)&counts[1] + 3));                        \
    }

PD_PC_ISR(PCINT0_vect, 0, PINB)
PD_PC_ISR(PCINT1_vect, 1, PINC)
PD_PC_ISR(PCINT2_vect, 2, PIND)

/* The slot of a pin-change counter on `pin` (bit, group), or 2: none. */
static uint8_t pc_slot(uint8_t bit, uint8_t group)
{
    for (uint8_t s = 0; s < 2u; s++) {
        if (pc_mask[s] == bit && (pc_mode[s] & 3u) == group) {
            return s;
        }
    }
    return 2u;
}

/* The count slot of a counter on `pin`, 2: none. */
static uint8_t count_slot(uint8_t pin)
{
    if (pin == 2u || pin == 3u) {
        return (uint8_t)(pin - 2u);
    }
    uint8_t bit;
    uint8_t group;
    (void)pcmsk(pin, &bit, &group);
    return pc_slot(bit, (uint8_t)(group >> 1));
}

#endif

/*
 * count += 1 with one register: subtracting 0xFF adds one, and the borrow is
 * set unless that byte wrapped, so each next byte subtracts 0xFF with it (adds
 * one only after a wrap). The compiler's handler saved seven registers for
 * the same: every byte of an interrupt's frame can land on the deepest stack
 * (test_stack_margin), and 36 cycles instead of 53 is a higher edge rate
 * counted without a loss.
 */
#define PD_COUNT_ISR(vector, n)                                              \
    ISR(vector, ISR_NAKED)                                                   \
    {                                                                        \
        __asm__ volatile("push r24\n\t"                                      \
                         "in r24, __SREG__\n\t"                              \
                         "push r24\n\t"                                      \
                         "lds r24, %[c0]\n\t"                                \
                         "subi r24, 0xFF\n\t"                                \
                         "sts %[c0], r24\n\t"                                \
                         "lds r24, %[c1]\n\t"                                \
                         "sbci r24, 0xFF\n\t"                                \
                         "sts %[c1], r24\n\t"                                \
                         "lds r24, %[c2]\n\t"                                \
                         "sbci r24, 0xFF\n\t"                                \
                         "sts %[c2], r24\n\t"                                \
                         "lds r24, %[c3]\n\t"                                \
                         "sbci r24, 0xFF\n\t"                                \
                         "sts %[c3], r24\n\t"                                \
                         "pop r24\n\t"                                       \
                         "out __SREG__, r24\n\t"                             \
                         "pop r24\n\t"                                       \
                         "reti\n\t"                                          \
                         :                                                   \
                         : [c0] "i"((uint8_t *)&counts[n] + 0),              \
                           [c1] "i"((uint8_t *)&counts[n] + 1),              \
                           [c2] "i"((uint8_t *)&counts[n] + 2),              \
                           [c3] "i"((uint8_t *)&counts[n] + 3));             \
    }

PD_COUNT_ISR(INT0_vect, 0)
PD_COUNT_ISR(INT1_vect, 1)
#if PD_BOARD_MEGA
PD_COUNT_ISR(INT2_vect, 2)
PD_COUNT_ISR(INT3_vect, 3)
PD_COUNT_ISR(INT4_vect, 4)
PD_COUNT_ISR(INT5_vect, 5)
#endif

/* EICRA's ISCn1:ISCn0 for an Edge (protoduino.proto): rising 11, falling 10, both 01. */
static const uint8_t sense[3] = {3u, 2u, 1u};

#if PD_AVR_PC_COUNTERS
/* A pin-change counter: PCMSK keeps the pin's bit (pd_avr_input_config set it). */
static void pc_start(uint8_t pin, uint8_t edge)
{
    uint8_t bit;
    uint8_t group;
    volatile uint8_t *mask = pcmsk(pin, &bit, &group);
    uint8_t g = (uint8_t)(group >> 1); /* PCIE0..2 -> 0..2 */
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        uint8_t s = pc_slot(bit, g);
        if (s == 2u) { /* a slot neither the other counter nor INT0/INT1 counts in */
            s = (pc_mask[0] != 0u || (EIMSK & _BV(INT0))) ? 1u : 0u;
        }
        uint8_t level = (uint8_t)(*pc_pins(mask) & bit);
        pc_mask[s] = bit;
        pc_mode[s] = (uint8_t)(g | (uint8_t)((edge < 3u ? edge : 2u) << 2) | (level ? 0x80u : 0u));
        counts[s] = 0;
        *mask |= bit;
        PCICR |= group;
    }
}
#endif

void pd_avr_counter_start(uint8_t pin, uint8_t edge)
{
#if PD_AVR_PC_COUNTERS
    if (pin != 2u && pin != 3u) {
        pc_start(pin, edge);
        return;
    }
#endif
    uint8_t n = PD_AVR_INT_OF(pin);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
#if PD_AVR_PC_COUNTERS
        if (pc_mask[n] != 0u) {
            /* A pin-change counter has this slot: it moves to the other one, free
             * (two counters at most, and this is not one of them yet). */
            pc_mask[1u - n] = pc_mask[n];
            pc_mode[1u - n] = pc_mode[n];
            counts[1u - n] = counts[n];
            pc_mask[n] = 0u;
        }
#endif
        /* No wake-up per edge (pd_avr_input_config gave it one): the loop reads the
         * count once per report interval, and at 40,000 edges a second a loop pass
         * per edge would take the whole CPU. PD2, PD3 are PCINT18, PCINT19. */
#if PD_BOARD_MEGA
        /* The Mega's INTn pins have no pin-change interrupt; INT4..INT7 sense in EICRB. */
        volatile uint8_t *eicr = n < 4u ? &EICRA : &EICRB;
        uint8_t at = (uint8_t)(2u * (n & 3u));
        EIMSK &= (uint8_t)~_BV(n);
        *eicr = (uint8_t)((*eicr & ~(3u << at)) | (sense[edge < 3u ? edge : 2u] << at));
#else
        PCMSK2 &= (uint8_t)~_BV(pin);
        EIMSK &= (uint8_t)~_BV(n);
        EICRA = (uint8_t)((EICRA & ~(3u << (2u * n))) | (sense[edge < 3u ? edge : 2u] << (2u * n)));
#endif
        EIFR = _BV(n); /* an edge from before does not count */
        counts[n] = 0;
        EIMSK |= _BV(n);
    }
}

uint32_t pd_avr_counter_read(uint8_t pin)
{
    uint32_t n = 0;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
#if PD_AVR_PC_COUNTERS
        uint8_t s = count_slot(pin);
        if (s < 2u) {
            n = counts[s];
        }
#else
        n = counts[PD_AVR_INT_OF(pin)];
#endif
    }
    return n;
}

void pd_avr_counter_stop(uint8_t pin)
{
#if PD_AVR_PC_COUNTERS
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        if (pin == 2u || pin == 3u) {
            EIMSK &= (uint8_t)~_BV(pin - 2u);
        } else {
            uint8_t s = count_slot(pin);
            if (s < 2u) {
                pc_mask[s] = 0u; /* its pin's changes only wake the loop, as an input's */
            }
        }
    }
#else
    EIMSK &= (uint8_t)~_BV(PD_AVR_INT_OF(pin));
#endif
}

#endif
