/* Area `pipes`: pipe and pipe2, data order across processes, end of file, O_NONBLOCK's
 * EAGAIN on both ends, EPIPE with SIGPIPE ignored and the SIGPIPE status otherwise, the
 * wrong end's EBADF, fstat and lseek of a pipe, F_GETFL/F_SETFL, FIONBIO and FIOCLEX. */
#include "check.h"

#include <fcntl.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/wait.h>

#define BIG (256 * 1024)

void area_pipes(void)
{
	int p[2];
	char buf[512];
	check_eq("pipe", 0, pipe(p));
	check_eq("write into the pipe", 5, write(p[1], "hello", 5));
	check_eq("read from the pipe", 5, read(p[0], buf, sizeof buf));
	check("pipe keeps the bytes", memcmp(buf, "hello", 5) == 0, "expected hello");
	check_errno("read of the write end EBADF", read(p[1], buf, 1), EBADF);
	check_errno("write into the read end EBADF", write(p[0], "x", 1), EBADF);
	check_errno("lseek of a pipe ESPIPE", lseek(p[0], 0, SEEK_CUR), ESPIPE);
	struct stat st;
	check("fstat says FIFO", fstat(p[0], &st) == 0 && S_ISFIFO(st.st_mode), "expected S_IFIFO");
	check_eq("F_GETFL of the read end", O_RDONLY, fcntl(p[0], F_GETFL) & O_ACCMODE);
	check_eq("F_GETFL of the write end", O_WRONLY, fcntl(p[1], F_GETFL) & O_ACCMODE);
	write(p[1], "ab", 2);
	close(p[1]);
	check_eq("data before end of file", 2, read(p[0], buf, sizeof buf));
	check_eq("end of file once the writer closed", 0, read(p[0], buf, sizeof buf));
	close(p[0]);

	check_eq("pipe2 O_CLOEXEC", 0, pipe2(p, O_CLOEXEC));
	check_eq("pipe2's ends are close-on-exec", FD_CLOEXEC,
		 fcntl(p[0], F_GETFD) & fcntl(p[1], F_GETFD));
	close(p[0]);
	close(p[1]);
	check_errno("pipe2 with a bad flag EINVAL", pipe2(p, 0x40000000), EINVAL);
	check_errno("pipe into a bad pointer EFAULT", syscall(SYS_pipe2, (int *)8, 0), EFAULT);

	/* Non-blocking ends. */
	check_eq("pipe2 O_NONBLOCK", 0, pipe2(p, O_NONBLOCK));
	check("F_GETFL says O_NONBLOCK", (fcntl(p[0], F_GETFL) & O_NONBLOCK) != 0,
	      "expected O_NONBLOCK");
	check_errno("read of an empty non-blocking pipe EAGAIN", read(p[0], buf, 1), EAGAIN);
	long filled = 0, n;
	memset(buf, 'z', sizeof buf);
	while ((n = write(p[1], buf, sizeof buf)) > 0 && filled < 16L << 20)
		filled += n;
	check("a full non-blocking pipe gives EAGAIN", n == -1 && errno == EAGAIN,
	      "expected EAGAIN got %s", n == -1 ? errno_name(errno) : "more room");
	check("a pipe holds at least 4096 bytes", filled >= 4096, "expected >= 4096");
	long drained = 0;
	while ((n = read(p[0], buf, sizeof buf)) > 0)
		drained += n;
	check_eq("reading the full pipe gives what was written", filled, drained);
	check_eq("F_SETFL clears O_NONBLOCK", 0, fcntl(p[0], F_SETFL, 0));
	check_eq("F_GETFL after F_SETFL", 0, fcntl(p[0], F_GETFL) & O_NONBLOCK);
	/* The ioctls every descriptor takes (Rust's std sets its pipes non-blocking so). */
	int on = 1;
	check_eq("FIONBIO sets O_NONBLOCK", 0, ioctl(p[0], FIONBIO, &on));
	check_errno("read after FIONBIO EAGAIN", read(p[0], buf, 1), EAGAIN);
	on = 0;
	check_eq("FIONBIO clears O_NONBLOCK", 0, ioctl(p[0], FIONBIO, &on));
	check_eq("F_GETFL after FIONBIO", 0, fcntl(p[0], F_GETFL) & O_NONBLOCK);
	check_eq("FIOCLEX", 0, ioctl(p[1], FIOCLEX));
	check_eq("F_GETFD after FIOCLEX", FD_CLOEXEC, fcntl(p[1], F_GETFD));
	check_eq("FIONCLEX", 0, ioctl(p[1], FIONCLEX));
	check_eq("F_GETFD after FIONCLEX", 0, fcntl(p[1], F_GETFD));
	close(p[0]);
	close(p[1]);

	/* A child writes more than the pipe holds; the parent reads all in order. */
	pipe(p);
	int pid = fork();
	if (pid == 0) {
		close(p[0]);
		char *data = malloc(BIG);
		if (!data)
			_exit(2);
		for (int i = 0; i < BIG; i++)
			data[i] = (char)(i * 7);
		/* A blocking write returns only when all is written (a short count is
		 * reported with exit 3, the rest still written for the order check). */
		long done = 0;
		int calls = 0;
		while (done < BIG) {
			long w = write(p[1], data + done, BIG - done);
			if (w <= 0)
				_exit(1);
			done += w;
			calls++;
		}
		_exit(calls == 1 ? 0 : 3);
	}
	close(p[1]);
	long got = 0;
	int in_order = 1;
	while ((n = read(p[0], buf, sizeof buf)) > 0) {
		for (long i = 0; i < n; i++)
			in_order &= buf[i] == (char)((got + i) * 7);
		got += n;
	}
	check_eq("reader gets all a child writes", BIG, got);
	check_eq("in order", 1, in_order);
	check_status("a blocking write of 256 KiB returns its whole count", wait_for(pid), 0, 0);
	close(p[0]);

	/* Blocking ping-pong between two processes. */
	int to[2], from[2];
	pipe(to);
	pipe(from);
	pid = fork();
	if (pid == 0) {
		char c;
		close(to[1]);
		close(from[0]);
		while (read(to[0], &c, 1) == 1) {
			c++;
			write(from[1], &c, 1);
		}
		_exit(0);
	}
	close(to[0]);
	close(from[1]);
	char c = 0;
	int rounds_ok = 1;
	for (int i = 0; i < 100; i++) {
		char sent = (char)i;
		rounds_ok &= write(to[1], &sent, 1) == 1 && read(from[0], &c, 1) == 1 &&
			     c == (char)(i + 1);
	}
	check_eq("100 round trips between two processes", 1, rounds_ok);
	close(to[1]);
	check_status("echo child ends at end of file", wait_for(pid), 0, 0);
	close(from[0]);

	/* Writing to a pipe without readers. */
	pipe(p);
	close(p[0]);
	pid = fork();
	if (pid == 0) {
		signal(SIGPIPE, SIG_IGN);
		long r = write(p[1], "x", 1);
		_exit(r == -1 && errno == EPIPE ? 0 : 1);
	}
	check_status("write without readers EPIPE when SIGPIPE is ignored", wait_for(pid), 0, 0);
	pid = fork();
	if (pid == 0) {
		write(p[1], "x", 1);
		_exit(0);
	}
	check_status("write without readers kills with SIGPIPE", wait_for(pid), -1, SIGPIPE);
	close(p[1]);
}
