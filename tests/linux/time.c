/* Area `time`: clock_gettime (monotonic never goes back, the real-time clock is set, the
 * process's CPU clock advances), clock_getres, gettimeofday and time agree with it,
 * nanosleep/clock_nanosleep/poll sleep at least as long as asked, and the errors. Checks
 * only lower bounds and orders, never how long something took. */
#include "check.h"

#include <poll.h>
#include <sys/time.h>
#include <time.h>

static long long ns(const struct timespec *t)
{
	return t->tv_sec * 1000000000LL + t->tv_nsec;
}

static long long monotonic(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return ns(&t);
}

void area_time(void)
{
	struct timespec a, b, res;
	check_eq("clock_gettime CLOCK_MONOTONIC", 0, clock_gettime(CLOCK_MONOTONIC, &a));
	int forward = 1;
	for (int i = 0; i < 1000; i++) {
		clock_gettime(CLOCK_MONOTONIC, &b);
		forward &= ns(&b) >= ns(&a);
		a = b;
	}
	check_eq("CLOCK_MONOTONIC never goes back (1000 reads)", 1, forward);
	check("tv_nsec below one second", a.tv_nsec >= 0 && a.tv_nsec < 1000000000,
	      "expected 0..999999999");
	check_eq("clock_gettime CLOCK_REALTIME", 0, clock_gettime(CLOCK_REALTIME, &a));
	check("the real-time clock is set (after 2020)", a.tv_sec > 1577836800,
	      "expected > 1577836800 got a time before 2020");
	struct timeval tv;
	check_eq("gettimeofday", 0, gettimeofday(&tv, NULL));
	check("gettimeofday agrees with CLOCK_REALTIME", tv.tv_sec - a.tv_sec >= 0 &&
							      tv.tv_sec - a.tv_sec <= 2,
	      "expected within 2 s");
	time_t t = time(NULL);
	check("time agrees with CLOCK_REALTIME", t - a.tv_sec >= 0 && t - a.tv_sec <= 2,
	      "expected within 2 s");
	check_eq("clock_getres CLOCK_MONOTONIC", 0, clock_getres(CLOCK_MONOTONIC, &res));
	check("monotonic resolution at most 1 ms", res.tv_sec == 0 && res.tv_nsec > 0 &&
							  res.tv_nsec <= 1000000,
	      "expected 0 < resolution <= 1 ms");
	check_errno("clock_gettime of a bad clock EINVAL", clock_gettime(12345, &a), EINVAL);
	check_eq("clock_gettime CLOCK_PROCESS_CPUTIME_ID", 0,
		 clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &a));
	volatile unsigned long spin = 0;
	long long until = monotonic() + 20000000;
	while (monotonic() < until)
		spin++;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &b);
	check("the process's CPU clock advances while it computes", ns(&b) > ns(&a),
	      "expected a later value");

	/* Sleeps last at least what they ask. */
	struct timespec twenty = { 0, 20000000 };
	long long start = monotonic();
	check_eq("nanosleep 20 ms", 0, nanosleep(&twenty, NULL));
	check("nanosleep slept at least 20 ms", monotonic() - start >= 20000000,
	      "expected >= 20 ms");
	start = monotonic();
	check_eq("clock_nanosleep 20 ms", 0, clock_nanosleep(CLOCK_MONOTONIC, 0, &twenty, NULL));
	check("clock_nanosleep slept at least 20 ms", monotonic() - start >= 20000000,
	      "expected >= 20 ms");
	clock_gettime(CLOCK_MONOTONIC, &a);
	a.tv_nsec += 20000000;
	if (a.tv_nsec >= 1000000000) {
		a.tv_sec++;
		a.tv_nsec -= 1000000000;
	}
	check_eq("clock_nanosleep TIMER_ABSTIME", 0,
		 clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &a, NULL));
	check("clock_nanosleep TIMER_ABSTIME woke after the time", monotonic() >= ns(&a),
	      "expected no earlier wake");
	start = monotonic();
	check_eq("poll without descriptors for 20 ms", 0, poll(NULL, 0, 20));
	check("poll slept at least 20 ms", monotonic() - start >= 20000000, "expected >= 20 ms");
	struct timespec bad = { 0, 1000000000 };
	check_errno("nanosleep with tv_nsec of one second EINVAL", nanosleep(&bad, NULL), EINVAL);
	bad.tv_sec = -1;
	bad.tv_nsec = 0;
	check_errno("nanosleep with a negative time EINVAL", nanosleep(&bad, NULL), EINVAL);
	check_eq("clock_nanosleep of a bad clock EINVAL", EINVAL,
		 clock_nanosleep(12345, 0, &twenty, NULL));
}
