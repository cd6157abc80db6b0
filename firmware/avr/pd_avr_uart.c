/*
 * USART0 with U2X, opening at PD_BAUD (a build option; 115200 by default: UBRR
 * 16, 2.1 % fast, the Arduino setting, well within what the Uno's USB bridge
 * accepts), and at 250,000, 500,000 or 1,000,000 baud once the host agreed on
 * one (UBRR 7, 3, 1: exact at 16 MHz; docs/protocol.md 5, *Line rate*). Our own driver rather than
 * the Arduino core's HardwareSerial: the same job in far less flash and RAM.
 *
 * Receive: an interrupt fills a ring buffer, so no byte is lost while the
 * main loop is busy. Transmit: the core queues whole frames into a second
 * ring and the data-register-empty interrupt sends them, so the loop never
 * waits for the line: while an Ack drains (1 ms for a servo command's, 9 ms
 * for a 64-byte ping echo) it decodes and runs the next command. The ring
 * holds the most one command can make the device send plus room for a
 * report (pd_link.h, PD_TX_RESERVE).
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <string.h>
#include <util/atomic.h>
#include <util/delay_basic.h>

#include "pd_avr.h"
#include "pd_link.h"


typedef char pd_assert_tx_size[PD_AVR_TX_SIZE <= 255 ? 1 : -1];
/* One slot stays free in a ring: the rest must take a command's replies and a report. */
typedef char pd_assert_tx_room[PD_AVR_TX_SIZE - 1u >= PD_TX_RESERVE ? 1 : -1];

typedef char pd_assert_rx_size[PD_AVR_RX_SIZE <= 255 ? 1 : -1];

static volatile uint8_t rx_buf[PD_AVR_RX_SIZE];
static volatile uint8_t rx_head; /* written by the ISR */
static volatile uint8_t rx_tail; /* written by the main loop */

static volatile uint8_t tx_buf[PD_AVR_TX_SIZE];
static volatile uint8_t tx_head; /* written by the main loop */
static volatile uint8_t tx_tail; /* written by the ISR */

static uint16_t ubrr_for(uint32_t baud)
{
    return (uint16_t)((F_CPU / 8u + baud / 2u) / baud - 1u);
}

/*
 * A new rate once every queued byte is out: the ring drains in the interrupt,
 * then the last byte leaves the shift register within one byte time at the old
 * rate (waited for in full: 11 bits, as simavr counts them, at 8 cycles a bit
 * with U2X, 4 cycles per _delay_loop_2 turn). The main loop waits here a few
 * ms at most, once or twice a session; bytes received meanwhile wait in the ring.
 */
void pd_avr_uart_set_baud(uint32_t baud)
{
    while (tx_head != tx_tail) {
    }
    while (!(UCSR0A & _BV(UDRE0))) {
    }
    uint16_t old = (uint16_t)(((uint16_t)UBRR0H << 8) | UBRR0L);
    _delay_loop_2((uint16_t)((old + 1u) * 24u));
    uint16_t ubrr = ubrr_for(baud);
    UBRR0H = (uint8_t)(ubrr >> 8);
    UBRR0L = (uint8_t)ubrr; /* simavr takes the new byte time from this write */
}

void pd_avr_uart_init(uint32_t baud)
{
    uint16_t ubrr = ubrr_for(baud);
    /* U2X before the rate, as the Arduino core does: simavr derives the byte
     * time from UBRR when UBRR0L is written and reads U2X only then, so the
     * other order emulates 57600 baud timing (the hardware does not care). */
    UCSR0A = _BV(U2X0);
    UBRR0H = (uint8_t)(ubrr >> 8);
    UBRR0L = (uint8_t)ubrr;
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0); /* UCSR0B_TX_IDLE below relies on this */
}

/*
 * Reading UDR0 clears the interrupt's cause, and the handler claims its slot of
 * the ring (rx_head moves on) before interrupts go back on: the servo interrupt
 * must not wait behind this one, or a pulse edge would be late by the rest of
 * this handler. Interrupts once went back on before the claim; but the USART
 * holds two received bytes, and when this handler starts late (behind another
 * one) the second is already there: RXC stays set after the read, so the
 * handler ran again on top of itself, and the nested one stored its byte in the
 * slot the outer one was about to fill (both had read rx_head). At 500,000 and
 * 1,000,000 baud (320 and 160 cycles a byte) that lost a frame now and then (a
 * CRC or COBS error, a retransmission); at 115200 the next byte is 1,389 cycles
 * away. Now a nested handler claims the next slot. The main loop cannot see a
 * claimed slot before its byte is in: it runs only once every handler returned.
 */
/*
 * In assembly, as the transmit handler below: the compiler's version saved eight
 * registers (r0, r1 and SREG among them) where four and SREG do, and this handler
 * runs for every byte received: about 11 cycles a byte less (bench part 5), and 3 B
 * less of the stack it lands on (the RAM budget). The same steps as before, in C:
 *
 *     byte = UDR0; head = rx_head; next = head + 1 == PD_AVR_RX_SIZE ? 0 : head + 1;
 *     if (next == rx_tail) return;   (lost: its frame fails its CRC; the host retries)
 *     rx_head = next; sei(); rx_buf[head] = byte;
 *     then a pass is due (PD_AVR_PASS) at a delimiter (with news), every second
 *     slot and a full ring (the return above: the loop must empty it).
 */
/* Both handlers' end: r31, r30, r25 back, then SREG and r24 as each saved them. */
#define PD_UART_ISR_RETURN                                                                    \
    "pop r31\n\t"                                                                            \
    "pop r30\n\t"                                                                            \
    "pop r25\n\t"                                                                            \
    "pop r24\n\t"                                                                            \
    "out __SREG__, r24\n\t"                                                                  \
    "pop r24\n\t"                                                                            \
    "reti\n\t"

ISR(USART_RX_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "push r25\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "lds r25, %[udr]\n\t"  /* the byte; reading it clears the interrupt's cause */
        "lds r30, %[head]\n\t" /* its slot */
        "mov r24, r30\n\t"
        "subi r24, 0xFF\n\t"   /* next = head + 1 */
        "cpi r24, %[size]\n\t"
        "brne 1f\n\t"
        "ldi r24, 0\n\t"
        "1:\n\t"
        "lds r31, %[tail]\n\t"
        "cp r24, r31\n\t"
        "breq 2f\n\t"           /* full: the byte is lost */
        "sts %[head], r24\n\t"  /* the slot claimed before interrupts go back on */
        "sei\n\t"
        "ldi r31, 0\n\t"
        "subi r30, lo8(-(%[buf]))\n\t"
        "sbci r31, hi8(-(%[buf]))\n\t"
        "st Z, r25\n\t"
        "tst r25\n\t"
        "brne 4f\n\t"
        "sbi %[pass], %[news]\n\t" /* a delimiter: a frame ended, a pass is due */
        "rjmp 2f\n\t"
        "4:\n\t"
        "andi r24, 1\n\t"      /* every second slot: a pass takes the bytes so far */
        "brne 3f\n\t"
        "2:\n\t"               /* (a full ring too: the loop must empty it) */
        "sbi %[pass], %[bit]\n\t"
        "3:\n\t"
        PD_UART_ISR_RETURN
        :
        : [udr] "n"(_SFR_MEM_ADDR(UDR0)), [head] "i"(&rx_head), [tail] "i"(&rx_tail),
          [buf] "i"(rx_buf), [size] "M"(PD_AVR_RX_SIZE), [pass] "I"(_SFR_IO_ADDR(PD_AVR_PASS)),
          [bit] "I"(PD_AVR_PASS_BIT), [news] "I"(PD_AVR_NEWS_BIT));
}

int16_t pd_avr_uart_peek(void)
{
    uint8_t tail = rx_tail;
    if (tail == rx_head) {
        return -1;
    }
    return rx_buf[tail];
}

void pd_avr_uart_drop(void)
{
    uint8_t next = (uint8_t)(rx_tail + 1u); /* one read of the volatile, not two */
    rx_tail = next == PD_AVR_RX_SIZE ? 0u : next;
}

bool pd_avr_uart_rx_empty(void)
{
    return rx_tail == rx_head;
}

bool pd_avr_uart_tx_empty(void)
{
    return tx_head == tx_tail;
}

uint8_t pd_avr_uart_tx_room(void)
{
    uint8_t head = tx_head;
    uint8_t tail = tx_tail;
    uint8_t used = (uint8_t)(head - tail);
    if (head < tail) {
        used = (uint8_t)(used + PD_AVR_TX_SIZE); /* wrapped: modulo 256, then back into range */
    }
    return (uint8_t)(PD_AVR_TX_SIZE - 1u - used);
}

bool pd_avr_uart_write(const uint8_t *data, uint16_t len)
{
    if (len > pd_avr_uart_tx_room()) {
        return false;
    }
    /* Up to the ring's end, then from its start: memcpy rather than a wrap
     * test per byte, on the path from a command's delimiter to its Ack's first
     * byte. The ISR reads only below tx_head, so these bytes are the main
     * loop's own until tx_head moves: no volatile access needed for them. */
    uint8_t head = tx_head;
    uint8_t *ring = (uint8_t *)tx_buf;
    uint8_t first = (uint8_t)(PD_AVR_TX_SIZE - head);
    if (len < first) {
        first = (uint8_t)len;
    }
    memcpy(ring + head, data, first);
    memcpy(ring, data + first, (uint8_t)(len - first));
    uint16_t next = (uint16_t)(head + len); /* up to 2 x 147: past a byte */
    if (next >= PD_AVR_TX_SIZE) {
        next = (uint16_t)(next - PD_AVR_TX_SIZE);
    }
    /* The copies are plain stores, which the compiler may move past a volatile
     * one: they must all be done before tx_head hands the bytes to the ISR. */
    __asm__ __volatile__("" ::: "memory");
    tx_head = (uint8_t)next; /* one byte: the ISR sees the whole frame or none of it */
    UCSR0B |= _BV(UDRIE0);
    return true;
}

/*
 * Data register empty: the ring's next byte into the data register, or nothing
 * (and the interrupt left off) when the ring is empty. The interrupt is
 * level-triggered (pending as long as the register is empty), so it must mask
 * itself before interrupts go back on, and until they do, a servo compare
 * interrupt waits behind it and its pulse edge is late: every cycle here
 * before `sei` is jitter at the servo pins. It masks with a constant store,
 * which touches no flag, and lets the servo in after 13 cycles (0.8 us).
 * UCSR0B's other bits never change after pd_avr_uart_init, so the constants
 * are its value without and with UDRIE0.
 *
 * In assembly, with four registers: the C function it called needed the
 * compiler's fifteen saved around it, and this handler's frame lands on top of
 * whatever the main loop is doing, its deepest stack included (the RAM budget,
 * tests/e2e/test_stack_margin.py): 7 B of stack where that took 19, and 32
 * cycles fewer per byte sent.
 */
#define UCSR0B_TX_IDLE (_BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0))
typedef char pd_assert_tx_index[PD_AVR_TX_SIZE <= 255 ? 1 : -1];

ISR(USART_UDRE_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "ldi r24, %[idle]\n\t"
        "sts %[ucsrb], r24\n\t"
        "sei\n\t"
        /* No instruction so far changed a flag: SREG is the interrupted code's. */
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "push r25\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "lds r24, %[tail]\n\t"
        "lds r25, %[head]\n\t"
        "cp r24, r25\n\t"
        "breq 1f\n\t" /* empty: the interrupt stays masked */
        "mov r30, r24\n\t"
        "ldi r31, 0\n\t"
        "subi r30, lo8(-(%[buf]))\n\t"
        "sbci r31, hi8(-(%[buf]))\n\t"
        "ld r25, Z\n\t"
        "sts %[udr], r25\n\t"
        "inc r24\n\t"
        "cpi r24, %[size]\n\t"
        "brne 2f\n\t"
        "ldi r24, 0\n\t"
        "2:\n\t"
        "sts %[tail], r24\n\t"
        "ldi r24, %[busy]\n\t"
        "sts %[ucsrb], r24\n\t"
        "rjmp 3f\n\t"
        "1:\n\t"
        "sbi %[pass], %[bit]\n\t" /* the ring emptied: a report or a held frame may go */
        "3:\n\t"
        PD_UART_ISR_RETURN
        :
        : [pass] "I"(_SFR_IO_ADDR(PD_AVR_PASS)), [bit] "I"(PD_AVR_PASS_BIT),
          [idle] "M"(UCSR0B_TX_IDLE), [busy] "M"(UCSR0B_TX_IDLE | _BV(UDRIE0)),
          [ucsrb] "n"(_SFR_MEM_ADDR(UCSR0B)), [udr] "n"(_SFR_MEM_ADDR(UDR0)),
          [tail] "i"(&tx_tail), [head] "i"(&tx_head), [buf] "i"(tx_buf),
          [size] "M"(PD_AVR_TX_SIZE));
}
