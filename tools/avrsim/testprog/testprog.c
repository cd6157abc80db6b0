/*
 * testprog.c: a small ATmega328P program that exercises the avrsim runner
 * without depending on the real firmware.
 *
 * Why it exists: the runner's pin measurement must be checked against a
 * known signal. This program produces the same kind of signal as the Arduino
 * Servo library (Timer1 in normal mode, a compare-A interrupt that ends one
 * channel's pulse and starts the next, a 20 ms frame) and keeps writing the
 * port that carries the pulses from its main loop, which is what makes
 * simavr 1.6 re-raise every output pin of that port (the "spurious pulses"
 * the runner has to filter out).
 *
 * UART0 at 115200 baud (U2X, as the Arduino core does): every received byte
 * is echoed back, and lines are also parsed as commands:
 *   S<pin> <us>   servo on pin 9 or 10 with that pulse width (attach if needed)
 *   X<pin>        stop the pulses on that servo pin (pin driven low)
 *   D<pin> <0|1>  pin 7, 8 or 13 as a digital output at that level
 *   P<pin> <duty> PWM duty 0..255 on pin 3 or 11 (Timer2 fast PWM, prescaler
 *                 64, 976 Hz, as Arduino's analogWrite; 0 and 255 are levels)
 *   U<pin> <0|1>  pin 2, 4 or 5 as an input, pull-up off/on
 *   R<pin>        answers "r<pin> <level>" (the PIN register bit, any pin 2..19)
 *   A<ch>         answers "a<ch> <counts>" (one ADC conversion of A<ch>, AVCC)
 *   E             answers "e <rising edges counted on INT0 (pin 2)>"
 * Answers follow the echo of the command line. Unknown lines are ignored
 * (they were echoed already).
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <stdint.h>

#define PD_BAUD_UBRR 16U /* 16 MHz / (8 * 117647): the Uno's usual 115200 with U2X */
#define PD_TICKS_PER_US 2U /* Timer1 prescaler 8 at 16 MHz: 0.5 us per tick */
#define PD_FRAME_TICKS (20000U * PD_TICKS_PER_US)
#define PD_CHANNELS 2U

/* Channel table: pin 9 = PB1, pin 10 = PB2. */
static const uint8_t pd_channel_bit[PD_CHANNELS] = {_BV(PB1), _BV(PB2)};
static volatile uint16_t pd_channel_ticks[PD_CHANNELS];
static volatile uint8_t pd_channel_active[PD_CHANNELS];
static volatile int8_t pd_current = -1;

static volatile uint16_t pd_int0_edges;

static volatile uint8_t pd_rx_buf[64];
static volatile uint8_t pd_rx_head;
static volatile uint8_t pd_rx_tail;

/* Servo-library style: end the current channel's pulse, start the next one,
 * or wait for the end of the 20 ms frame. */
ISR(TIMER1_COMPA_vect)
{
    if (pd_current < 0) {
        TCNT1 = 0; /* start of a new frame */
    } else if (pd_channel_active[pd_current]) {
        PORTB &= (uint8_t)~pd_channel_bit[pd_current];
    }
    pd_current++;
    if ((uint8_t)pd_current < PD_CHANNELS) {
        OCR1A = TCNT1 + pd_channel_ticks[pd_current];
        if (pd_channel_active[pd_current]) {
            PORTB |= pd_channel_bit[pd_current];
        }
    } else {
        uint16_t now = TCNT1;
        OCR1A = (now + 8U < PD_FRAME_TICKS) ? PD_FRAME_TICKS : (uint16_t)(now + 8U);
        pd_current = -1;
    }
}

ISR(INT0_vect)
{
    pd_int0_edges++;
}

ISR(USART_RX_vect)
{
    uint8_t c = UDR0;
    uint8_t next = (uint8_t)((pd_rx_head + 1U) % sizeof pd_rx_buf);
    if (next != pd_rx_tail) {
        pd_rx_buf[pd_rx_head] = c;
        pd_rx_head = next;
    }
}

static void pd_putc(uint8_t c)
{
    while (!(UCSR0A & _BV(UDRE0))) {
    }
    UDR0 = c;
}

static int pd_getc(void)
{
    if (pd_rx_head == pd_rx_tail) {
        return -1;
    }
    uint8_t c = pd_rx_buf[pd_rx_tail];
    pd_rx_tail = (uint8_t)((pd_rx_tail + 1U) % sizeof pd_rx_buf);
    return c;
}

static void pd_puts(const char *s)
{
    while (*s) {
        pd_putc((uint8_t)*s++);
    }
}

static void pd_putu(uint16_t v)
{
    char buf[6];
    uint8_t n = 0;
    do {
        buf[n++] = (char)('0' + v % 10U);
        v /= 10U;
    } while (v);
    while (n) {
        pd_putc((uint8_t)buf[--n]);
    }
}

static void pd_answer(char tag, int16_t index, uint16_t value)
{
    pd_putc((uint8_t)tag);
    if (index >= 0) {
        pd_putu((uint16_t)index);
    }
    pd_putc(' ');
    pd_putu(value);
    pd_puts("\n");
}

static volatile uint8_t *pd_pin_reg(uint16_t pin)
{
    return pin < 8U ? &PIND : (pin < 14U ? &PINB : &PINC);
}

static uint8_t pd_bit(uint16_t pin)
{
    return (uint8_t)(1U << (pin < 8U ? pin : (pin < 14U ? pin - 8U : pin - 14U)));
}

static uint16_t pd_adc(uint8_t ch)
{
    ADMUX = (uint8_t)(_BV(REFS0) | (ch & 7U)); /* AVCC reference */
    ADCSRA = _BV(ADEN) | _BV(ADSC) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
    while (ADCSRA & _BV(ADSC)) {
    }
    return ADC;
}

/* Pin 3 = OC2B (PD3), pin 11 = OC2A (PB3). */
static void pd_pwm(uint16_t pin, uint16_t duty)
{
    uint8_t com = pin == 3U ? _BV(COM2B1) : _BV(COM2A1);
    volatile uint8_t *port = pin == 3U ? &PORTD : &PORTB;
    uint8_t bit = pin == 3U ? _BV(PD3) : _BV(PB3);
    TCCR2A |= _BV(WGM21) | _BV(WGM20); /* fast PWM, TOP = 0xFF */
    TCCR2B = _BV(CS22);                /* prescaler 64 */
    if (duty == 0U || duty >= 255U) {
        if (duty) {
            *port |= bit;
        } else {
            *port &= (uint8_t)~bit;
        }
        TCCR2A &= (uint8_t)~com;
    } else {
        /* High for (OCR + 1) / 256 of the period: the nearest to duty / 255. */
        uint8_t ocr = (uint8_t)(((uint32_t)duty * 512U / 255U + 1U) / 2U - 1U);
        if (pin == 3U) {
            OCR2B = ocr;
        } else {
            OCR2A = ocr;
        }
        TCCR2A |= com;
    }
    if (pin == 3U) {
        DDRD |= bit;
    } else {
        DDRB |= bit;
    }
}

static int8_t pd_channel_of(uint16_t pin)
{
    if (pin == 9U) {
        return 0;
    }
    if (pin == 10U) {
        return 1;
    }
    return -1;
}

static void pd_command(const char *line)
{
    char op = line[0];
    uint16_t pin = 0;
    uint16_t arg = 0;
    const char *p = line + 1;
    while (*p >= '0' && *p <= '9') {
        pin = (uint16_t)(pin * 10U + (uint16_t)(*p++ - '0'));
    }
    while (*p == ' ') {
        p++;
    }
    while (*p >= '0' && *p <= '9') {
        arg = (uint16_t)(arg * 10U + (uint16_t)(*p++ - '0'));
    }
    int8_t ch = pd_channel_of(pin);
    if (op == 'S' && ch >= 0 && arg >= 100U && arg <= 3000U) {
        uint16_t ticks = (uint16_t)(arg * PD_TICKS_PER_US);
        cli();
        pd_channel_ticks[ch] = ticks;
        pd_channel_active[ch] = 1;
        sei();
        DDRB |= pd_channel_bit[ch];
    } else if (op == 'X' && ch >= 0) {
        cli();
        pd_channel_active[ch] = 0;
        PORTB &= (uint8_t)~pd_channel_bit[ch];
        sei();
    } else if (op == 'D' && (pin == 7U || pin == 8U || pin == 13U)) {
        volatile uint8_t *port = pin == 7U ? &PORTD : &PORTB;
        volatile uint8_t *ddr = pin == 7U ? &DDRD : &DDRB;
        uint8_t bit = pd_bit(pin);
        if (arg) {
            *port |= bit;
        } else {
            *port &= (uint8_t)~bit;
        }
        *ddr |= bit;
    } else if (op == 'P' && (pin == 3U || pin == 11U) && arg <= 255U) {
        pd_pwm(pin, arg);
    } else if (op == 'U' && (pin == 2U || pin == 4U || pin == 5U)) {
        uint8_t bit = pd_bit(pin);
        DDRD &= (uint8_t)~bit;
        if (arg) {
            PORTD |= bit;
        } else {
            PORTD &= (uint8_t)~bit;
        }
    } else if (op == 'R' && pin >= 2U && pin <= 19U) {
        pd_answer('r', (int16_t)pin, (*pd_pin_reg(pin) & pd_bit(pin)) ? 1U : 0U);
    } else if (op == 'A' && pin <= 5U) {
        pd_answer('a', (int16_t)pin, pd_adc((uint8_t)pin));
    } else if (op == 'E') {
        cli();
        uint16_t edges = pd_int0_edges;
        sei();
        pd_answer('e', -1, edges);
    }
}

int main(void)
{
    /* U2X first: simavr computes the byte time when UBRR0L is written. */
    UCSR0A = _BV(U2X0);
    UBRR0 = PD_BAUD_UBRR;
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);

    for (uint8_t i = 0; i < PD_CHANNELS; i++) {
        pd_channel_ticks[i] = 1500U * PD_TICKS_PER_US;
    }
    TCCR1A = 0;
    TCCR1B = _BV(CS11); /* prescaler 8, normal mode */
    TCNT1 = 0;
    OCR1A = 100U;
    TIFR1 = _BV(OCF1A);
    TIMSK1 = _BV(OCIE1A);
    EICRA = _BV(ISC01) | _BV(ISC00); /* INT0 on rising edges */
    EIMSK = _BV(INT0);
    sei();

    char line[24];
    uint8_t len = 0;
    for (;;) {
        /* Rewrite PORTB with its own value: on simavr 1.6 every such write
         * re-raises each output pin's IRQ, the artefact the runner filters. */
        PORTB |= _BV(PB4);
        PORTB &= (uint8_t)~_BV(PB4);

        int c = pd_getc();
        if (c < 0) {
            continue;
        }
        pd_putc((uint8_t)c);
        if (c == '\n' || c == '\r') {
            line[len] = '\0';
            if (len > 0) {
                pd_command(line);
            }
            len = 0;
        } else if (len < sizeof line - 1U) {
            line[len++] = (char)c;
        }
    }
}
