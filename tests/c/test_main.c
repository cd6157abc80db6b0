/* Runs every test table; prints one line per failure and "N passed, M failed". */
#include <stdlib.h>
#include <string.h>

#include "pd_features.h"
#include "pd_test.h"

int pd_test_failed_flag;
static const char *current;

void pd_test_fail(const char *file, int line, const char *expr, long long a, long long b)
{
    pd_test_failed_flag = 1;
    fprintf(stderr, "FAIL %s (%s:%d): %s", current, file, line, expr);
    if (a != b) {
        fprintf(stderr, " [%lld != %lld]", a, b);
    }
    fprintf(stderr, "\n");
}

int main(int argc, char **argv)
{
    const pd_test_case_t *tables[] = {pd_tests_codec, pd_tests_encode, pd_tests_link,
                                      pd_tests_dispatch, pd_tests_failsafe, pd_tests_motion, pd_tests_pwm, pd_tests_inputs,
                                      pd_tests_engine,
#if PD_FEATURE_USER
                                      pd_tests_user,
#endif
    };
    const char *only = argc > 1 ? argv[1] : NULL; /* run tests whose name contains it */
    int passed = 0;
    int failed = 0;

    for (size_t t = 0; t < sizeof(tables) / sizeof(tables[0]); t++) {
        for (const pd_test_case_t *tc = tables[t]; tc->fn; tc++) {
            if (only && !strstr(tc->name, only)) {
                continue;
            }
            current = tc->name;
            pd_test_failed_flag = 0;
            tc->fn();
            if (pd_test_failed_flag) {
                failed++;
            } else {
                passed++;
            }
        }
    }
    printf("%d passed, %d failed\n", passed, failed);
    return failed == 0 && passed > 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}
