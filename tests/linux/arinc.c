/* linux-arinc: the guest's ARINC 653 ports as Linux devices, /dev/arinc/<port>
 * (partitions/guest/src/arinc.rs), from a Linux program.
 *
 *     linux-arinc check
 *         checks read, write, poll, O_NONBLOCK, the validity ioctl and the errors of the
 *         port devices of scenario system_devices (tests/configs/system_devices.toml):
 *         sample-out -> sample-in (sampling, 16 bytes, refresh 50 ms) and queue-out ->
 *         queue-in (queuing, 32 bytes, depth 2 each), both looped back to the guest by
 *         channels; plc-request -> the PLC's online port and its answer on plc-response
 *         (queuing, 256 bytes); level, the plant's level (sampling, 8 bytes, refresh
 *         100 ms). Prints `ok <check>` or `FAIL <check>: ...` lines (check.h), never a
 *         pid, an address or a time, then `arinc: all checks passed` (exit 0) or
 *         `arinc: <n> checks failed` (exit 1).
 *
 *     linux-arinc flood REQUEST RESPONSE SECONDS
 *         the port flood of scenario system_hostile_guest: for SECONDS, as fast as it can,
 *         non-blocking writes to the PLC's online request port REQUEST (valid READ, LIST
 *         and STATS requests, a FORCE, and garbage of random length) and non-blocking
 *         reads of every answer from RESPONSE; each call is a request to syssw. Prints
 *         `flood: <n> port calls, <n> requests sent, <n> refused (queue full), <n> answers
 *         (<n> OK, <n> FORBIDDEN, <n> MALFORMED, <n> other)`; exit 0, 2 on a bad argument,
 *         3 when a port cannot be opened. */
#include "check.h"

#include <fcntl.h>
#include <poll.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/uio.h>
#include <sys/wait.h>
#include <time.h>

/* The validity of a sampling port's message: `_IOR('A', 1, int)`, 1 valid, 0 not. */
#define ARINC_IOCTL_VALIDITY _IOR('A', 1, int)
/* The port devices' major number. */
#define ARINC_MAJOR 240

#define SAMPLE_SIZE 16
#define QUEUE_SIZE 32
#define ONLINE_SIZE 256

/* The PLC online protocol (partitions/softplc/online): op, seq, payload. */
enum { OP_LIST = 1, OP_READ = 2, OP_FORCE = 4, OP_STATS = 6 };
enum { STATUS_OK = 0, STATUS_MALFORMED = 1, STATUS_FORBIDDEN = 5 };
/* The bytecode's type code of LREAL. */
#define TYPE_LREAL 10

static int open_port(const char *name, int flags)
{
	char path[64];
	snprintf(path, sizeof path, "/dev/arinc/%s", name);
	return open(path, flags);
}

/* The poll events of `fd` for `events`, after waiting at most `ms` (0 when none). */
static int poll_events(int fd, short events, int ms)
{
	struct pollfd p = { .fd = fd, .events = events };
	int n = poll(&p, 1, ms);
	return n == 1 ? p.revents : n == 0 ? 0 : -1;
}

static int validity(int fd)
{
	int valid = -1;
	if (ioctl(fd, ARINC_IOCTL_VALIDITY, &valid) != 0)
		return -1;
	return valid;
}

static void sleep_ms(long ms)
{
	struct timespec t = { .tv_sec = ms / 1000, .tv_nsec = (ms % 1000) * 1000000L };
	while (nanosleep(&t, &t) == -1 && errno == EINTR)
		;
}

/* Reads one message of `fd` and expects the text `want` (its length and bytes). */
static void check_message(const char *name, int fd, size_t size, const char *want)
{
	char buf[ONLINE_SIZE];
	memset(buf, 0, sizeof buf);
	ssize_t n = read(fd, buf, size);
	int e = errno;
	size_t len = strlen(want);
	if (n == -1)
		check(name, 0, "expected \"%s\" got -1 (%s)", want, errno_name(e));
	else
		check(name, (size_t)n == len && memcmp(buf, want, len) == 0,
		      "expected \"%s\" (%zu bytes) got \"%.*s\" (%zd bytes)", want, len, (int)n,
		      buf, n);
}

static void device_files(void)
{
	struct stat st;
	int r = stat("/dev/arinc/sample-in", &st);
	check("stat: a character device", r == 0 && S_ISCHR(st.st_mode), "expected S_IFCHR");
	check_eq("stat: major 240", ARINC_MAJOR, r == 0 ? (long)major(st.st_rdev) : -1);
	struct stat other;
	check("stat: each port its own minor",
	      stat("/dev/arinc/queue-in", &other) == 0 && other.st_rdev != st.st_rdev,
	      "expected another device number");
	check_errno("open of a port that is not configured ENOENT",
		    open_port("no-such-port", O_RDONLY), ENOENT);
}

static void sampling(void)
{
	char buf[64];
	int in = open_port("sample-in", O_RDONLY | O_NONBLOCK);
	check_ok("sampling: open the destination O_NONBLOCK", in);
	int out = open_port("sample-out", O_WRONLY);
	check_ok("sampling: open the source", out);

	/* Before the first message. */
	check_errno("sampling: read before any message EAGAIN", read(in, buf, SAMPLE_SIZE), EAGAIN);
	check_eq("sampling: no POLLIN before any message", 0, poll_events(in, POLLIN, 0));
	check_eq("sampling: invalid before any message", 0, validity(in));
	check_eq("sampling: the source has POLLOUT", POLLOUT, poll_events(out, POLLOUT, 0));

	/* One message, read as often as wanted while it is fresh. */
	check_eq("sampling: write one message", 15, write(out, "hello, sampling", 15));
	check_eq("sampling: POLLIN once written", POLLIN, poll_events(in, POLLIN, 0));
	check_eq("sampling: the message is valid", 1, validity(in));
	check_message("sampling: read gives the message", in, SAMPLE_SIZE, "hello, sampling");
	check_message("sampling: a second read gives it again", in, sizeof buf, "hello, sampling");

	/* Sizes. */
	check_errno("sampling: a read buffer smaller than the port EMSGSIZE", read(in, buf, 8),
		    EMSGSIZE);
	memset(buf, 'x', sizeof buf);
	check_errno("sampling: a write longer than the port EMSGSIZE",
		    write(out, buf, SAMPLE_SIZE + 1), EMSGSIZE);
	check_eq("sampling: a write of the port's size", SAMPLE_SIZE, write(out, buf, SAMPLE_SIZE));
	check_eq("sampling: a read of the port's size", SAMPLE_SIZE, read(in, buf, SAMPLE_SIZE));
	check_eq("sampling: a write of 0 bytes sends nothing", 0, write(out, buf, 0));

	/* Older than the destination's refresh period (50 ms): invalid, still readable. */
	check_eq("sampling: write before the pause", 5, write(out, "stale", 5));
	sleep_ms(150);
	check_eq("sampling: invalid after the refresh period", 0, validity(in));
	check_eq("sampling: an invalid message still has POLLIN", POLLIN, poll_events(in, POLLIN, 0));
	check_message("sampling: the invalid message is still read", in, SAMPLE_SIZE, "stale");
	check_eq("sampling: write a fresh message", 5, write(out, "fresh", 5));
	check_eq("sampling: valid again", 1, validity(in));
	check_message("sampling: read the fresh message", in, SAMPLE_SIZE, "fresh");

	/* Wrong directions and calls. */
	int both = open_port("sample-in", O_RDWR);
	check_errno("sampling: write to a destination EINVAL", write(both, "x", 1), EINVAL);
	close(both);
	both = open_port("sample-out", O_RDWR);
	check_errno("sampling: read of a source EINVAL", read(both, buf, SAMPLE_SIZE), EINVAL);
	check_errno("sampling: validity of a source ENOTTY", validity(both), ENOTTY);
	close(both);
	check_errno("sampling: read of a write-only descriptor EBADF", read(out, buf, SAMPLE_SIZE),
		    EBADF);
	check_errno("sampling: pread ESPIPE", pread(in, buf, SAMPLE_SIZE, 0), ESPIPE);
	check_errno("sampling: another ioctl ENOTTY", ioctl(in, TCGETS, buf), ENOTTY);
	close(in);
	close(out);
}

static void queuing(void)
{
	char buf[64];
	int in = open_port("queue-in", O_RDONLY | O_NONBLOCK);
	check_ok("queuing: open the destination O_NONBLOCK", in);
	int out = open_port("queue-out", O_WRONLY | O_NONBLOCK);
	check_ok("queuing: open the source O_NONBLOCK", out);

	check_errno("queuing: read of an empty queue EAGAIN", read(in, buf, QUEUE_SIZE), EAGAIN);
	check_eq("queuing: no POLLIN on an empty queue", 0, poll_events(in, POLLIN, 0));
	check_eq("queuing: poll waits 100 ms for nothing", 0, poll_events(in, POLLIN, 100));
	check_eq("queuing: the source has POLLOUT", POLLOUT, poll_events(out, POLLOUT, 0));
	check_errno("queuing: a queuing port has no validity ENOTTY", validity(in), ENOTTY);

	/* Depth 2 + 2: four messages fit, the fifth does not. */
	const char *words[] = { "one", "two", "three", "four" };
	for (int i = 0; i < 4; i++) {
		char name[64];
		snprintf(name, sizeof name, "queuing: send message %d", i + 1);
		check_eq(name, (long)strlen(words[i]), write(out, words[i], strlen(words[i])));
	}
	check_errno("queuing: a full queue EAGAIN", write(out, "five", 4), EAGAIN);
	check_eq("queuing: no POLLOUT on a full queue", 0, poll_events(out, POLLOUT, 0));
	check_eq("queuing: POLLIN with messages", POLLIN, poll_events(in, POLLIN, 0));
	check_errno("queuing: a read buffer smaller than the port EMSGSIZE", read(in, buf, 8),
		    EMSGSIZE);
	check_message("queuing: the first message first (EMSGSIZE took nothing)", in, QUEUE_SIZE,
		      "one");
	check_eq("queuing: POLLOUT once one was taken", POLLOUT, poll_events(out, POLLOUT, 0));
	check_message("queuing: then the second", in, QUEUE_SIZE, "two");
	check_message("queuing: then the third", in, sizeof buf, "three");
	check_message("queuing: then the fourth", in, QUEUE_SIZE, "four");
	check_errno("queuing: empty again EAGAIN", read(in, buf, QUEUE_SIZE), EAGAIN);

	memset(buf, 'q', sizeof buf);
	check_errno("queuing: a write longer than the port EMSGSIZE", write(out, buf, QUEUE_SIZE + 1),
		    EMSGSIZE);
	check_eq("queuing: a message of the port's size", QUEUE_SIZE, write(out, buf, QUEUE_SIZE));
	check_eq("queuing: read it whole", QUEUE_SIZE, read(in, buf, sizeof buf));

	/* writev: one message per buffer; readv: one message per buffer, up to a message
	 * shorter than its buffer. */
	struct iovec two[2] = { { "alpha", 5 }, { "beta", 4 } };
	check_eq("queuing: writev of two buffers", 9, writev(out, two, 2));
	char first[QUEUE_SIZE], second[QUEUE_SIZE];
	struct iovec into[2] = { { first, sizeof first }, { second, sizeof second } };
	check_eq("queuing: readv stops after a shorter message", 5, readv(in, into, 2));
	check("queuing: readv's first buffer holds the first message",
	      memcmp(first, "alpha", 5) == 0, "expected alpha");
	check_message("queuing: writev sent the second buffer as a message", in, QUEUE_SIZE, "beta");

	/* O_NONBLOCK by fcntl, both ways. */
	int blocking = open_port("queue-in", O_RDONLY);
	check_eq("queuing: F_SETFL O_NONBLOCK", 0, fcntl(blocking, F_SETFL, O_NONBLOCK));
	check_errno("queuing: then a read of the empty queue EAGAIN", read(blocking, buf, QUEUE_SIZE),
		    EAGAIN);
	check_eq("queuing: F_SETFL clears it", 0, fcntl(blocking, F_SETFL, 0));

	/* A blocking read waits for a message another process sends; poll waits for it. */
	int pid = fork();
	if (pid == 0) {
		sleep_ms(50);
		int w = open_port("queue-out", O_WRONLY);
		if (write(w, "late", 4) != 4)
			_exit(1);
		sleep_ms(50);
		_exit(write(w, "later", 5) == 5 ? 0 : 1);
	}
	check_eq("queuing: poll waits for a message from another process", POLLIN,
		 poll_events(in, POLLIN, 5000));
	check_message("queuing: which is read", in, QUEUE_SIZE, "late");
	check_message("queuing: a blocking read waits for the next one", blocking, QUEUE_SIZE,
		      "later");
	check_status("queuing: the sender exited", wait_for(pid), 0, 0);

	/* A blocking write to a full queue waits until another process takes a message. */
	for (int i = 0; i < 4; i++)
		write(out, words[i], strlen(words[i]));
	pid = fork();
	if (pid == 0) {
		sleep_ms(50);
		char b[QUEUE_SIZE];
		_exit(read(in, b, sizeof b) == 3 ? 0 : 1);
	}
	int blocking_out = open_port("queue-out", O_WRONLY);
	check_eq("queuing: a blocking write waits for room", 4, write(blocking_out, "five", 4));
	check_status("queuing: the reader took one", wait_for(pid), 0, 0);
	check_message("queuing: the rest in order (2)", in, QUEUE_SIZE, "two");
	check_message("queuing: the rest in order (3)", in, QUEUE_SIZE, "three");
	check_message("queuing: the rest in order (4)", in, QUEUE_SIZE, "four");
	check_message("queuing: the rest in order (5)", in, QUEUE_SIZE, "five");
	check_errno("queuing: drained EAGAIN", read(in, buf, QUEUE_SIZE), EAGAIN);
	close(blocking);
	close(blocking_out);
	close(in);
	close(out);
}

/* Both directions with another partition: a READ request to the PLC, its answer. */
static void partner(void)
{
	int request = open_port("plc-request", O_WRONLY);
	check_ok("plc: open the request port", request);
	int response = open_port("plc-response", O_RDONLY);
	check_ok("plc: open the response port", response);
	const char read_valve[] = { OP_READ, 42, 'v', 'a', 'l', 'v', 'e' };
	check_eq("plc: write a READ request", sizeof read_valve,
		 write(request, read_valve, sizeof read_valve));
	check_eq("plc: poll waits for the answer", POLLIN, poll_events(response, POLLIN, 5000));
	unsigned char answer[ONLINE_SIZE];
	check_eq("plc: read the answer (head, LREAL)", 12, read(response, answer, sizeof answer));
	check("plc: the answer is OK, LREAL", answer[0] == OP_READ && answer[1] == 42 &&
		      answer[2] == STATUS_OK && answer[3] == TYPE_LREAL,
	      "expected 2 42 0 10 got %d %d %d %d", answer[0], answer[1], answer[2], answer[3]);
	double valve;
	memcpy(&valve, answer + 4, sizeof valve);
	check("plc: the valve is between 0 and 1", valve >= 0.0 && valve <= 1.0, "got %g", valve);
	close(request);
	close(response);

	int level = open_port("level", O_RDONLY);
	check_ok("plant: open the level port", level);
	double value = -1;
	check_eq("plant: read the level (8 bytes)", 8, read(level, &value, sizeof value));
	check_eq("plant: the level is valid", 1, validity(level));
	check("plant: the level is between 0 and 2 m", value >= 0.0 && value <= 2.0, "got %g",
	      value);
	close(level);
}

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec + t.tv_nsec / 1e9;
}

static int flood(const char *request_path, const char *response_path, double seconds)
{
	int request = open(request_path, O_WRONLY | O_NONBLOCK);
	int response = open(response_path, O_RDONLY | O_NONBLOCK);
	if (request < 0 || response < 0) {
		say("flood: cannot open the ports: %s", errno_name(errno));
		return 3;
	}
	static const char *names[] = { "level", "valve", "alarm", "tank.pid.integral" };
	unsigned long calls = 0, sent = 0, refused = 0, answers = 0, ok = 0, forbidden = 0, malformed = 0,
		      other = 0;
	uint32_t random = 0x2545f491;
	unsigned char m[ONLINE_SIZE];
	double end = now_s() + seconds;
	for (unsigned long i = 0; now_s() < end; i++) {
		size_t len;
		m[1] = (unsigned char)i;
		switch (i % 5) {
		case 0:
		case 1: {
			const char *name = names[i % 4];
			m[0] = OP_READ;
			len = strlen(name);
			memcpy(m + 2, name, len);
			len += 2;
			break;
		}
		case 2:
			m[0] = OP_LIST;
			m[2] = m[3] = 0;
			len = 4;
			break;
		case 3: /* a FORCE the PLC's access level refuses */
			m[0] = OP_FORCE;
			m[2] = TYPE_LREAL;
			memset(m + 3, 0, 8);
			memcpy(m + 11, "valve", 5);
			len = 16;
			break;
		default: /* garbage of random length */
			len = 1 + random % ONLINE_SIZE;
			for (size_t b = 0; b < len; b++) {
				random ^= random << 13;
				random ^= random >> 17;
				random ^= random << 5;
				m[b] = (unsigned char)random;
			}
			break;
		}
		calls++;
		if (write(request, m, len) == (ssize_t)len)
			sent++;
		else if (errno == EAGAIN)
			refused++;
		unsigned char a[ONLINE_SIZE];
		for (calls++; read(response, a, sizeof a) > 2; calls++) {
			answers++;
			if (a[2] == STATUS_OK)
				ok++;
			else if (a[2] == STATUS_FORBIDDEN)
				forbidden++;
			else if (a[2] == STATUS_MALFORMED)
				malformed++;
			else
				other++;
		}
	}
	say("flood: %lu port calls, %lu requests sent, %lu refused (queue full), %lu answers (%lu OK, "
	    "%lu FORBIDDEN, %lu MALFORMED, %lu other)",
	    calls, sent, refused, answers, ok, forbidden, malformed, other);
	return 0;
}

int main(int argc, char **argv)
{
	self_path = argv[0];
	if (argc == 5 && strcmp(argv[1], "flood") == 0)
		return flood(argv[2], argv[3], atof(argv[4]));
	if (argc != 2 || strcmp(argv[1], "check") != 0) {
		say("usage: linux-arinc check | linux-arinc flood REQUEST RESPONSE SECONDS");
		return 2;
	}
	device_files();
	sampling();
	queuing();
	partner();
	if (failures == 0)
		say("arinc: all checks passed");
	else
		say("arinc: %d checks failed", failures);
	return failures == 0 ? 0 : 1;
}
