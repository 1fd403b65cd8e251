/* linux-bench: the guest benchmark, in TSC cycles, after the method of Table 1 of the
 * P4Linux paper ("The performance of µ-kernel-based systems"): each metric is a loop of
 * `--loops` calls (default 1000) timed with rdtsc, divided by the number of calls, repeated
 * `--rounds` times (default 5); the line gives the median, minimum and maximum over the
 * rounds:
 *
 *     bench <prefix><metric> median=<n> min=<n> max=<n> unit=cycles samples=<rounds>
 *
 * (the line format of `cargo xtask bench`; prefix `guest_` unless `--prefix` says
 * otherwise, e.g. `host_` for the same program on the host). Metrics:
 *
 *   getpid            one getpid system call
 *   getppid           one getppid system call (in the guest a round trip through the guest
 *                     partition, where the kernel answers a thread's later getpids itself)
 *   fork_exit         fork, the child _exits, the parent waits for it
 *   vfork_exit        the same with vfork
 *   fork_execve       fork, the child executes this program (`--exit 0`), the parent waits
 *   vfork_execve      the same with vfork
 *   pipe_roundtrip    one byte to a child process and back through two pipes
 *   shell_echo_cat    (per run, not per call) `sh -c` running 200 times
 *                     `echo $i | cat > /dev/null` (cat's output goes into a pipe this
 *                     program drains when there is no /dev/null; a `note` line says so)
 *   gzip_4mib         (per run) `busybox gzip -c` of 4 MiB of text fed through a pipe, its
 *                     output drained through another
 *   bash_script       (per run) `/bin/bash -c` running a loop of 100 rounds with arithmetic,
 *                     string operations, a `[[ =~ ]]` match and a `$(...)` subshell each,
 *                     its result checked by the script (skipped with a `note` line when
 *                     there is no /bin/bash)
 *   bash_no_subshell  (per run) the same script with `printf -v` in place of the subshell:
 *                     what bash_script costs besides its 100 forks
 *   tcp_roundtrip     one byte to a child process and back over a TCP connection on the
 *                     loopback (127.0.0.1)
 *   tcp_4mib          (per run) 4 MiB from a child process over a loopback TCP
 *                     connection, in 64 KiB writes
 *
 * and, only when named (they need a file system to write to, `--dir`), the disk metrics,
 * timed with CLOCK_MONOTONIC instead of the TSC, each line in its own unit:
 *
 *   disk_write_seq    (MB/s = 10^6 bytes a second; per run) a file of `--disk-kib` KiB
 *                     (default 1024) created in DIR, written in 64 KiB writes and
 *                     fsync'd: from the open to the end of the fsync
 *   disk_read_seq     (MB/s; per run) the same file read back in 64 KiB reads after the
 *                     caches were dropped (untimed): with `--remount DEV`, DIR unmounted
 *                     and DEV mounted there again as ext2 (both the guest and Linux then
 *                     read from the disk); without it, 3 written to
 *                     /proc/sys/vm/drop_caches (a `note` line says which)
 *   disk_fsync        (us per call) 4 KiB written at the start of a file of DIR and
 *                     fsync'd, `--fsync-loops` calls a round (default 50)
 *
 *     linux-bench [--loops N] [--fork-loops N] [--rounds N] [--prefix P]
 *                 [--dir DIR] [--remount DEV] [--disk-kib N] [--fsync-loops N] [METRIC...]
 *
 * `--fork-loops` sets the loop length of the four process metrics on their own (they cost
 * milliseconds per call where fork copies the address space). Must be started with an
 * absolute path (it executes itself). Exits 1 when a metric could not be measured. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/mount.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <x86intrin.h>

#define MAX_ROUNDS 64

static const char *self;
static const char *prefix = "guest_";
static long loops = 1000, fork_loops = 1000;
static int rounds = 5;
static int broken;

static unsigned long long now(void)
{
	_mm_lfence();
	return __rdtsc();
}

static void fail(const char *what)
{
	printf("bench-error %s: %s\n", what, strerror(errno));
	fflush(stdout);
	broken = 1;
}

static int wait_child(int pid)
{
	int status;
	while (waitpid(pid, &status, 0) == -1)
		if (errno != EINTR)
			return -1;
	return status;
}

static int by_value(const void *a, const void *b)
{
	unsigned long long x = *(const unsigned long long *)a, y = *(const unsigned long long *)b;
	return x < y ? -1 : x > y;
}

/* Prints the line of `name` from the per-call cycles of each round. */
static void report(const char *name, unsigned long long *values, int n)
{
	qsort(values, n, sizeof values[0], by_value);
	unsigned long long median = n % 2 ? values[n / 2] : (values[n / 2 - 1] + values[n / 2]) / 2;
	printf("bench %s%s median=%llu min=%llu max=%llu unit=cycles samples=%d\n", prefix, name,
	       median, values[0], values[n - 1], n);
	fflush(stdout);
}

static int getpid_round(long n)
{
	for (long i = 0; i < n; i++)
		syscall(SYS_getpid);
	return 0;
}

static int getppid_round(long n)
{
	for (long i = 0; i < n; i++)
		syscall(SYS_getppid);
	return 0;
}

static int fork_round(long n, int use_vfork, int exec)
{
	char *args[] = { (char *)self, "--exit", "0", NULL };
	char *env[] = { NULL };
	for (long i = 0; i < n; i++) {
		int pid = use_vfork ? vfork() : fork();
		if (pid == 0) {
			if (exec)
				execve(self, args, env);
			_exit(exec ? 99 : 0);
		}
		if (pid < 0) {
			fail(use_vfork ? "vfork" : "fork");
			return -1;
		}
		int status = wait_child(pid);
		if (status != 0) {
			printf("bench-error child status 0x%x\n", status);
			broken = 1;
			return -1;
		}
	}
	return 0;
}
static int fork_exit_round(long n)
{
	return fork_round(n, 0, 0);
}
static int vfork_exit_round(long n)
{
	return fork_round(n, 1, 0);
}
static int fork_execve_round(long n)
{
	return fork_round(n, 0, 1);
}
static int vfork_execve_round(long n)
{
	return fork_round(n, 1, 1);
}

/* The echo child of the round trips lives over all rounds. */
static int to_child[2] = { -1, -1 }, from_child[2] = { -1, -1 };
static int echo_pid;

static int pipe_roundtrip_round(long n)
{
	if (echo_pid == 0) {
		if (pipe(to_child) || pipe(from_child)) {
			fail("pipe");
			return -1;
		}
		echo_pid = fork();
		if (echo_pid == 0) {
			char c;
			close(to_child[1]);
			close(from_child[0]);
			while (read(to_child[0], &c, 1) == 1)
				if (write(from_child[1], &c, 1) != 1)
					_exit(1);
			_exit(0);
		}
		close(to_child[0]);
		close(from_child[1]);
	}
	char c = 'x';
	for (long i = 0; i < n; i++)
		if (write(to_child[1], &c, 1) != 1 || read(from_child[0], &c, 1) != 1) {
			fail("pipe round trip");
			return -1;
		}
	return 0;
}

static void end_echo_child(void)
{
	if (echo_pid > 0) {
		close(to_child[1]);
		close(from_child[0]);
		wait_child(echo_pid);
		echo_pid = 0;
	}
}

/* Runs `argv` with its stdin from `feed` (or nothing) and its stdout into a pipe this
 * process drains; returns the number of bytes it printed, -1 on failure. `feed` runs in a
 * child of its own writing into the program's stdin. */
static long run_drained(char *const argv[], void (*feed)(int fd))
{
	int out[2], in[2] = { -1, -1 };
	if (pipe(out) || (feed && pipe(in))) {
		fail("pipe");
		return -1;
	}
	int pid = fork();
	if (pid == 0) {
		dup2(out[1], 1);
		close(out[0]);
		close(out[1]);
		if (feed) {
			dup2(in[0], 0);
			close(in[0]);
			close(in[1]);
		}
		char *env[] = { "PATH=/bin:/usr/bin", NULL };
		execve(argv[0], argv, env);
		_exit(127);
	}
	close(out[1]);
	int feeder = 0;
	if (feed) {
		close(in[0]);
		feeder = fork();
		if (feeder == 0) {
			close(out[0]);
			feed(in[1]);
			_exit(0);
		}
		close(in[1]);
	}
	char buf[4096];
	long total = 0, n;
	while ((n = read(out[0], buf, sizeof buf)) > 0)
		total += n;
	close(out[0]);
	int status = wait_child(pid);
	int fed = feeder > 0 ? wait_child(feeder) : 0;
	if (pid < 0 || status != 0 || feeder < 0 || fed != 0) {
		printf("bench-error %s ended with status 0x%x, its feeder with 0x%x\n", argv[0],
		       status, fed);
		broken = 1;
		return -1;
	}
	return total;
}

static int have_dev_null(void)
{
	int fd = open("/dev/null", O_WRONLY);
	if (fd < 0)
		return 0;
	int ok = write(fd, "x", 1) == 1;
	close(fd);
	return ok;
}

static int shell_round(long n)
{
	(void)n;
	char *with_null[] = { "/bin/sh", "-c",
			      "i=0; while [ $i -lt 200 ]; do echo $i | cat > /dev/null; i=$((i+1)); done",
			      NULL };
	char *drained[] = { "/bin/sh", "-c",
			    "i=0; while [ $i -lt 200 ]; do echo $i | cat; i=$((i+1)); done", NULL };
	return run_drained(have_dev_null() ? with_null : drained, NULL) < 0 ? -1 : 0;
}

#define GZIP_BYTES (4L << 20)

/* Writes all of `data` (a pipe may take it in parts); exits 1 if it cannot. */
static void write_all(int fd, const char *data, size_t len)
{
	while (len > 0) {
		ssize_t n = write(fd, data, len);
		if (n <= 0)
			_exit(1);
		data += n;
		len -= n;
	}
}

/* 4 MiB of text that compresses like prose: words from a small list, picked by a fixed
 * xorshift sequence. */
static void gzip_input(int fd)
{
	static const char *words[] = { "the ", "guest ", "partition ", "runs ", "a ", "static ",
				       "Linux ", "binary ", "as ", "microkernel ", "task, ",
				       "served ", "by ", "its ", "personality.\n" };
	static char buf[65536];
	unsigned long x = 88172645463325252UL;
	long sent = 0;
	size_t used = 0;
	while (sent < GZIP_BYTES) {
		x ^= x << 13;
		x ^= x >> 7;
		x ^= x << 17;
		const char *w = words[x % (sizeof words / sizeof words[0])];
		size_t len = strlen(w);
		if (used + len > sizeof buf || sent + (long)(used + len) > GZIP_BYTES) {
			write_all(fd, buf, used);
			sent += used;
			used = 0;
			if (sent + (long)len > GZIP_BYTES) {
				long rest = GZIP_BYTES - sent;
				memset(buf, '.', rest);
				write_all(fd, buf, rest);
				break;
			}
		}
		memcpy(buf + used, w, len);
		used += len;
	}
	close(fd);
}

static int gzip_round(long n)
{
	(void)n;
	char *argv[] = { "/bin/busybox", "gzip", "-c", NULL };
	long compressed = run_drained(argv, gzip_input);
	if (compressed >= 0 && compressed < 64 * 1024) {
		/* 4 MiB of these words compress to a few hundred KiB, never this little. */
		printf("bench-error gzip wrote only %ld bytes\n", compressed);
		broken = 1;
		return -1;
	}
	return compressed < 0 ? -1 : 0;
}

/* The bash macro: each round forks a subshell for `$(...)` (printf is a builtin: no
 * execve), the rest is bash's own work, which `bash_no_subshell` measures alone with
 * `printf -v`. The script exits 1 if its result is not the one bash computes on the host. */
static int bash_run(const char *format)
{
	char script[512];
	snprintf(script, sizeof script,
		 "s= n=0\n"
		 "for ((i = 0; i < 100; i++)); do\n"
		 "\t%s\n"
		 "\ts+=${w:1:2}\n"
		 "\t((n += ${#w} + i %% 3))\n"
		 "\t[[ $w =~ ^0 ]] && ((n++))\n"
		 "done\n"
		 "u=${s//0/o}\n"
		 "[[ \"${#u} $n ${u:0:12}\" == '200 408 oo3774114885' ]]\n",
		 format);
	char *argv[] = { "/bin/bash", "-c", script, NULL };
	return run_drained(argv, NULL) < 0 ? -1 : 0;
}

static int bash_round(long n)
{
	(void)n;
	return bash_run("w=$(printf '%03d' $((i * 37 % 1000)))");
}

static int bash_no_subshell_round(long n)
{
	(void)n;
	return bash_run("printf -v w '%03d' $((i * 37 % 1000))");
}

/* A loopback TCP connection to a child: this process's end, the child's pid in *child,
 * which runs `serve` on its end and exits. -1 on failure. */
static int tcp_child(int *child, void (*serve)(int fd))
{
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	socklen_t len = sizeof a;
	int one = 1;
	int l = socket(AF_INET, SOCK_STREAM, 0);
	if (l < 0 || bind(l, (struct sockaddr *)&a, sizeof a) || listen(l, 1) ||
	    getsockname(l, (struct sockaddr *)&a, &len)) {
		fail("listen on 127.0.0.1");
		return -1;
	}
	*child = fork();
	if (*child == 0) {
		int fd = socket(AF_INET, SOCK_STREAM, 0);
		if (fd < 0 || connect(fd, (struct sockaddr *)&a, sizeof a))
			_exit(1);
		setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
		serve(fd);
		_exit(0);
	}
	int fd = accept(l, NULL, NULL);
	close(l);
	if (fd < 0) {
		fail("accept");
		return -1;
	}
	setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
	return fd;
}

static void tcp_echo(int fd)
{
	char c;
	while (read(fd, &c, 1) == 1)
		if (write(fd, &c, 1) != 1)
			_exit(1);
}

static int tcp_fd = -1, tcp_pid;

static int tcp_roundtrip_round(long n)
{
	if (tcp_fd < 0 && (tcp_fd = tcp_child(&tcp_pid, tcp_echo)) < 0)
		return -1;
	char c = 'x';
	for (long i = 0; i < n; i++)
		if (write(tcp_fd, &c, 1) != 1 || read(tcp_fd, &c, 1) != 1) {
			fail("TCP round trip");
			return -1;
		}
	return 0;
}

static void end_tcp_child(void)
{
	if (tcp_fd >= 0) {
		close(tcp_fd);
		wait_child(tcp_pid);
		tcp_fd = -1;
	}
}

#define TCP_BYTES (4L << 20)

static void tcp_send_4mib(int fd)
{
	static char buf[65536];
	memset(buf, 'z', sizeof buf);
	for (long sent = 0; sent < TCP_BYTES; sent += sizeof buf)
		write_all(fd, buf, sizeof buf);
}

static int tcp_4mib_round(long n)
{
	(void)n;
	int pid;
	int fd = tcp_child(&pid, tcp_send_4mib);
	if (fd < 0)
		return -1;
	static char buf[65536];
	long got = 0, r;
	while ((r = read(fd, buf, sizeof buf)) > 0)
		got += r;
	close(fd);
	if (wait_child(pid) != 0 || got != TCP_BYTES) {
		printf("bench-error tcp_4mib received %ld bytes\n", got);
		broken = 1;
		return -1;
	}
	return 0;
}

/* The disk metrics: their directory, the device to mount there again before a read. */
static const char *disk_dir;
static const char *remount_dev;
static long disk_kib = 1024, fsync_loops = 50;
#define DISK_BLOCK 65536L
#define FSYNC_BYTES 4096

static double seconds(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec + t.tv_nsec / 1e9;
}

static const char *disk_path(const char *name)
{
	static char path[4096];
	snprintf(path, sizeof path, "%s/%s", disk_dir, name);
	return path;
}

static char disk_buf[DISK_BLOCK];

/* Writes the sequential file (`--disk-kib` KiB in 64 KiB writes) and fsyncs it; -1 on
 * failure. */
static int write_seq_file(void)
{
	for (long i = 0; i < DISK_BLOCK; i++)
		disk_buf[i] = (char)(i * 7 + (i >> 9));
	int fd = open(disk_path("seq"), O_WRONLY | O_CREAT | O_TRUNC, 0644);
	if (fd < 0) {
		fail("open the sequential file for writing");
		return -1;
	}
	long bytes = disk_kib * 1024;
	for (long done = 0; done < bytes; done += DISK_BLOCK) {
		long len = bytes - done < DISK_BLOCK ? bytes - done : DISK_BLOCK;
		if (write(fd, disk_buf, len) != len) {
			fail("write the sequential file");
			close(fd);
			return -1;
		}
	}
	if (fsync(fd)) {
		fail("fsync the sequential file");
		close(fd);
		return -1;
	}
	return close(fd);
}

/* MB/s of one write of the sequential file, -1 on failure. */
static double disk_write_seq_round(void)
{
	double start = seconds();
	if (write_seq_file() < 0)
		return -1;
	return disk_kib * 1024 / (seconds() - start) / 1e6;
}

/* Drops the caches between a write and a read (see the header). */
static int drop_caches(void)
{
	if (remount_dev) {
		if (umount(disk_dir)) {
			fail("umount the disk directory");
			return -1;
		}
		if (mount(remount_dev, disk_dir, "ext2", 0, NULL)) {
			fail("mount the disk again");
			return -1;
		}
		return 0;
	}
	sync();
	int fd = open("/proc/sys/vm/drop_caches", O_WRONLY);
	if (fd < 0 || write(fd, "3\n", 2) != 2) {
		fail("write /proc/sys/vm/drop_caches");
		if (fd >= 0)
			close(fd);
		return -1;
	}
	return close(fd);
}

/* MB/s of one read of the sequential file after the caches were dropped. */
static double disk_read_seq_round(void)
{
	struct stat st;
	if ((stat(disk_path("seq"), &st) || st.st_size != disk_kib * 1024) &&
	    write_seq_file() < 0)
		return -1;
	if (drop_caches() < 0)
		return -1;
	double start = seconds();
	int fd = open(disk_path("seq"), O_RDONLY);
	if (fd < 0) {
		fail("open the sequential file for reading");
		return -1;
	}
	long got = 0, n;
	while ((n = read(fd, disk_buf, DISK_BLOCK)) > 0)
		got += n;
	close(fd);
	double elapsed = seconds() - start;
	if (n < 0 || got != disk_kib * 1024) {
		printf("bench-error disk_read_seq read %ld bytes of %ld\n", got, disk_kib * 1024);
		broken = 1;
		return -1;
	}
	return got / elapsed / 1e6;
}

/* us per call of `--fsync-loops` writes of 4 KiB at the start of a file, each fsync'd. */
static double disk_fsync_round(void)
{
	int fd = open(disk_path("fsync"), O_WRONLY | O_CREAT, 0644);
	if (fd < 0) {
		fail("open the fsync file");
		return -1;
	}
	double start = seconds();
	for (long i = 0; i < fsync_loops; i++) {
		disk_buf[0] = (char)i;
		if (pwrite(fd, disk_buf, FSYNC_BYTES, 0) != FSYNC_BYTES || fsync(fd)) {
			fail("write and fsync 4 KiB");
			close(fd);
			return -1;
		}
	}
	double elapsed = seconds() - start;
	close(fd);
	return elapsed / fsync_loops * 1e6;
}

static const struct {
	const char *name;
	const char *unit;
	double (*round)(void);
	int warm_up; /* one untimed round first */
} disk_metrics[] = {
	{ "disk_write_seq", "MB/s", disk_write_seq_round, 0 },
	{ "disk_read_seq", "MB/s", disk_read_seq_round, 0 },
	{ "disk_fsync", "us", disk_fsync_round, 1 },
};
#define DISK_METRICS (sizeof disk_metrics / sizeof disk_metrics[0])

static int by_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

static void measure_disk(size_t m)
{
	double values[MAX_ROUNDS];
	if (!disk_dir) {
		printf("bench-error %s needs --dir\n", disk_metrics[m].name);
		broken = 1;
		return;
	}
	if (strcmp(disk_metrics[m].name, "disk_read_seq") == 0) {
		if (remount_dev)
			printf("note %s%s: caches dropped by umount and mount of %s on %s\n", prefix,
			       disk_metrics[m].name, remount_dev, disk_dir);
		else
			printf("note %s%s: caches dropped through /proc/sys/vm/drop_caches\n", prefix,
			       disk_metrics[m].name);
		fflush(stdout);
	}
	if (disk_metrics[m].warm_up && disk_metrics[m].round() < 0)
		return;
	for (int r = 0; r < rounds; r++)
		if ((values[r] = disk_metrics[m].round()) < 0)
			return;
	qsort(values, rounds, sizeof values[0], by_double);
	double median = rounds % 2 ? values[rounds / 2]
				   : (values[rounds / 2 - 1] + values[rounds / 2]) / 2;
	printf("bench %s%s median=%.3f min=%.3f max=%.3f unit=%s samples=%d\n", prefix,
	       disk_metrics[m].name, median, values[0], values[rounds - 1], disk_metrics[m].unit,
	       rounds);
	fflush(stdout);
}

static const struct {
	const char *name;
	int (*round)(long n);
	int process; /* loops of --fork-loops */
	int per_run; /* one run per round, not per call */
} metrics[] = {
	{ "getpid", getpid_round, 0, 0 },
	{ "getppid", getppid_round, 0, 0 },
	{ "fork_exit", fork_exit_round, 1, 0 },
	{ "vfork_exit", vfork_exit_round, 1, 0 },
	{ "fork_execve", fork_execve_round, 1, 0 },
	{ "vfork_execve", vfork_execve_round, 1, 0 },
	{ "pipe_roundtrip", pipe_roundtrip_round, 0, 0 },
	{ "shell_echo_cat", shell_round, 0, 1 },
	{ "gzip_4mib", gzip_round, 0, 1 },
	{ "bash_script", bash_round, 0, 1 },
	{ "bash_no_subshell", bash_no_subshell_round, 0, 1 },
	{ "tcp_roundtrip", tcp_roundtrip_round, 0, 0 },
	{ "tcp_4mib", tcp_4mib_round, 0, 1 },
};
#define METRICS (sizeof metrics / sizeof metrics[0])

static void measure(size_t m)
{
	unsigned long long values[MAX_ROUNDS];
	long n = metrics[m].per_run ? 1 : metrics[m].process ? fork_loops : loops;
	if (metrics[m].per_run && strcmp(metrics[m].name, "shell_echo_cat") == 0 &&
	    !have_dev_null()) {
		printf("note %s%s: no /dev/null, cat writes into a pipe\n", prefix, metrics[m].name);
		fflush(stdout);
	}
	if ((metrics[m].round == bash_round || metrics[m].round == bash_no_subshell_round) &&
	    access("/bin/bash", X_OK) != 0) {
		printf("note %s%s: no /bin/bash, skipped\n", prefix, metrics[m].name);
		fflush(stdout);
		return;
	}
	/* A short warm-up round for the per-call metrics (page faults, the echo child). */
	if (!metrics[m].per_run && metrics[m].round(n < 10 ? n : 10) < 0)
		return;
	for (int r = 0; r < rounds; r++) {
		unsigned long long start = now();
		if (metrics[m].round(n) < 0)
			return;
		values[r] = (now() - start) / n;
	}
	end_echo_child();
	end_tcp_child();
	report(metrics[m].name, values, rounds);
}

static long number(const char *s, long max)
{
	char *end;
	long v = strtol(s, &end, 10);
	if (*end || v < 1 || v > max) {
		fprintf(stderr, "linux-bench: %s: expected 1..%ld\n", s, max);
		exit(2);
	}
	return v;
}

int main(int argc, char **argv)
{
	self = argv[0];
	if (argc == 3 && strcmp(argv[1], "--exit") == 0)
		return atoi(argv[2]);
	int chosen = 0;
	int selected[METRICS] = { 0 }, disk_selected[DISK_METRICS] = { 0 };
	for (int i = 1; i < argc; i++) {
		if (strcmp(argv[i], "--loops") == 0 && i + 1 < argc)
			loops = number(argv[++i], 1000000);
		else if (strcmp(argv[i], "--fork-loops") == 0 && i + 1 < argc)
			fork_loops = number(argv[++i], 1000000);
		else if (strcmp(argv[i], "--rounds") == 0 && i + 1 < argc)
			rounds = number(argv[++i], MAX_ROUNDS);
		else if (strcmp(argv[i], "--prefix") == 0 && i + 1 < argc)
			prefix = argv[++i];
		else if (strcmp(argv[i], "--dir") == 0 && i + 1 < argc)
			disk_dir = argv[++i];
		else if (strcmp(argv[i], "--remount") == 0 && i + 1 < argc)
			remount_dev = argv[++i];
		else if (strcmp(argv[i], "--disk-kib") == 0 && i + 1 < argc)
			disk_kib = number(argv[++i], 1 << 20);
		else if (strcmp(argv[i], "--fsync-loops") == 0 && i + 1 < argc)
			fsync_loops = number(argv[++i], 1000000);
		else {
			size_t m = 0, d = 0;
			while (m < METRICS && strcmp(metrics[m].name, argv[i]) != 0)
				m++;
			while (d < DISK_METRICS && strcmp(disk_metrics[d].name, argv[i]) != 0)
				d++;
			if (m == METRICS && d == DISK_METRICS) {
				fprintf(stderr, "linux-bench: unknown metric or option %s\n", argv[i]);
				return 2;
			}
			if (m < METRICS)
				selected[m] = 1;
			else
				disk_selected[d] = 1;
			chosen = 1;
		}
	}
	for (size_t m = 0; m < METRICS; m++)
		if (!chosen || selected[m])
			measure(m);
	/* The disk metrics only when named. */
	for (size_t d = 0; d < DISK_METRICS; d++)
		if (disk_selected[d])
			measure_disk(d);
	return broken;
}
