/*
 * A tiny test harness: TEST() functions, CHECK macros that report file, line
 * and values and end the test, and a runner that prints "N passed, M failed".
 */
#ifndef PD_TEST_H
#define PD_TEST_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

extern int pd_test_failed_flag;

void pd_test_fail(const char *file, int line, const char *expr, long long a, long long b);

#define CHECK(cond)                                                                                \
    do {                                                                                           \
        if (!(cond)) {                                                                             \
            pd_test_fail(__FILE__, __LINE__, #cond, 0, 0);                                         \
            return;                                                                                \
        }                                                                                          \
    } while (0)

#define CHECK_EQ(a, b)                                                                             \
    do {                                                                                           \
        long long pd_a_ = (long long)(a), pd_b_ = (long long)(b);                                  \
        if (pd_a_ != pd_b_) {                                                                      \
            pd_test_fail(__FILE__, __LINE__, #a " == " #b, pd_a_, pd_b_);                          \
            return;                                                                                \
        }                                                                                          \
    } while (0)

typedef void (*pd_test_fn)(void);
typedef struct pd_test_case {
    const char *name;
    pd_test_fn fn;
} pd_test_case_t;

#define TEST_CASE(fn) {#fn, fn}

/* Each test file exports its table. */
extern const pd_test_case_t pd_tests_codec[];
extern const pd_test_case_t pd_tests_link[];
extern const pd_test_case_t pd_tests_dispatch[];
extern const pd_test_case_t pd_tests_motion[];
extern const pd_test_case_t pd_tests_pwm[];
extern const pd_test_case_t pd_tests_inputs[];
extern const pd_test_case_t pd_tests_failsafe[];
extern const pd_test_case_t pd_tests_encode[];
extern const pd_test_case_t pd_tests_engine[];
/* Only in `make unit-user` (PD_FEATURE_USER, with tests/c/user/probe.proto). */
extern const pd_test_case_t pd_tests_user[];

#endif /* PD_TEST_H */
