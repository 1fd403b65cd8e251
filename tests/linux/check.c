/* The checks' common part (check.h): how a check reports and waits, shared by
 * `linux-tests` and `linux-arinc`. */
#include "check.h"

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
