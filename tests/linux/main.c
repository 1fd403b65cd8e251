/* linux-tests: checks of Linux system calls' results and error codes, run the same way on
 * the host Linux and in the Warden guest, whose outputs must be the same.
 *
 *     linux-tests AREA...     run the areas in order (process memory files writes pipes
 *                             signals time misc); no argument: all of them
 *
 * Each area prints `ok <check>` or `FAIL <check>: expected X got Y` lines and then
 * `area <name>: all checks passed` or `area <name>: <n> checks failed`; the program exits
 * 0 when all its areas passed, 1 otherwise, 2 on a bad argument. It must be started with
 * an absolute path (some checks execute it again: `--exit`, `--args`, `--fd-closed`,
 * `--dispositions`). tests/linux/expected/<area>.out holds each area's expected output. */
#include "check.h"

#include <stdlib.h>
#include <sys/wait.h>

int failures;
const char *self_path;

void say(const char *fmt, ...)
{
	char line[512];
	va_list ap;
	va_start(ap, fmt);
	int n = vsnprintf(line, sizeof line - 1, fmt, ap);
	va_end(ap);
	if (n < 0)
		return;
	if (n > (int)sizeof line - 2)
		n = sizeof line - 2;
	line[n++] = '\n';
	const char *p = line;
	while (n > 0) {
		ssize_t w = write(1, p, n);
		if (w <= 0)
			return;
		p += w;
		n -= w;
	}
}

void check(const char *name, int cond, const char *fmt, ...)
{
	if (cond) {
		say("ok %s", name);
		return;
	}
	char detail[400];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(detail, sizeof detail, fmt, ap);
	va_end(ap);
	say("FAIL %s: %s", name, detail);
	failures++;
}

const char *errno_name(int e)
{
	static char number[16];
	const char *name = strerrorname_np(e);
	if (name)
		return name;
	snprintf(number, sizeof number, "%d", e);
	return number;
}

void check_eq(const char *name, long expected, long got)
{
	int e = errno;
	if (got == -1 && expected != -1)
		check(name, 0, "expected %ld got -1 (%s)", expected, errno_name(e));
	else
		check(name, expected == got, "expected %ld got %ld", expected, got);
}

void check_errno(const char *name, long ret, int expected)
{
	int e = errno;
	if (ret == -1)
		check(name, e == expected, "expected %s got %s", errno_name(expected), errno_name(e));
	else
		check(name, 0, "expected %s got %ld", errno_name(expected), ret);
}

void check_ok(const char *name, long ret)
{
	int e = errno;
	check(name, ret != -1, "expected success got %s", errno_name(e));
}

static void describe_status(char *out, size_t size, int status)
{
	if (status == -1)
		snprintf(out, size, "no status (%s)", errno_name(errno));
	else if (WIFEXITED(status))
		snprintf(out, size, "exit %d", WEXITSTATUS(status));
	else if (WIFSIGNALED(status))
		snprintf(out, size, "signal %d", WTERMSIG(status));
	else
		snprintf(out, size, "status 0x%x", status);
}

void check_status(const char *name, int status, int code, int signal)
{
	char want[64], got[64];
	int good = code >= 0 ? status != -1 && WIFEXITED(status) && WEXITSTATUS(status) == code
			     : status != -1 && WIFSIGNALED(status) && WTERMSIG(status) == signal;
	if (code >= 0)
		snprintf(want, sizeof want, "exit %d", code);
	else
		snprintf(want, sizeof want, "signal %d", signal);
	describe_status(got, sizeof got, status);
	check(name, good, "expected %s got %s", want, got);
}

int wait_for(int pid)
{
	int status;
	if (pid < 0)
		return -1;
	for (;;) {
		int r = wait4(pid, &status, 0, NULL);
		if (r == pid)
			return status;
		if (r == -1 && errno == EINTR)
			continue;
		return -1;
	}
}

static const struct {
	const char *name;
	void (*run)(void);
} areas[] = {
	{ "process", area_process }, { "memory", area_memory }, { "files", area_files },
	{ "writes", area_writes },   { "pipes", area_pipes },   { "signals", area_signals },
	{ "time", area_time },	     { "misc", area_misc },
};
#define AREAS (sizeof areas / sizeof areas[0])

static int run_area(const char *name)
{
	for (size_t i = 0; i < AREAS; i++) {
		if (strcmp(areas[i].name, name) != 0)
			continue;
		failures = 0;
		areas[i].run();
		if (failures == 0)
			say("area %s: all checks passed", name);
		else
			say("area %s: %d checks failed", name, failures);
		return failures == 0;
	}
	say("unknown area %s", name);
	exit(2);
}

int main(int argc, char **argv)
{
	self_path = argv[0];
	if (argc > 1 && strncmp(argv[1], "--", 2) == 0)
		return exec_mode(argc, argv);
	int passed = 1;
	if (argc == 1) {
		for (size_t i = 0; i < AREAS; i++)
			passed &= run_area(areas[i].name);
	} else {
		for (int i = 1; i < argc; i++)
			passed &= run_area(argv[i]);
	}
	return passed ? 0 : 1;
}
