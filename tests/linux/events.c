/* Area `events`: eventfd (the counter, semaphore mode, O_NONBLOCK's EAGAIN, the EINVAL
 * cases, poll readiness, a read that waits for another process's write), timerfd (one-shot
 * and interval expirations, absolute times on both clocks, gettime, the old value, the
 * errors, poll) and epoll (level- and edge-triggered reports on a pipe, EPOLLONESHOT,
 * the epoll_ctl and epoll_wait errors, an item staying while a dup of its descriptor is
 * open and leaving the interest list with the last one, timeouts, a timer and an eventfd
 * in an interest list, epoll_pwait's mask and a signal interrupting a wait, nesting). Timers are short (10-30 ms); the checks count only
 * expirations that must have happened and lower bounds of times. */
#include "check.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/syscall.h>
#include <sys/time.h>
#include <sys/timerfd.h>
#include <sys/wait.h>
#include <time.h>

#define MS 1000000LL

static long long now_ns(clockid_t clock)
{
	struct timespec t;
	clock_gettime(clock, &t);
	return t.tv_sec * 1000000000LL + t.tv_nsec;
}

static struct timespec span(long long ns)
{
	struct timespec t = { .tv_sec = ns / 1000000000LL, .tv_nsec = ns % 1000000000LL };
	return t;
}

static long long ns_of(struct timespec t)
{
	return t.tv_sec * 1000000000LL + t.tv_nsec;
}

/* Reads the 8-byte value of an eventfd or timerfd (-1 with errno when the read fails). */
static long long read_u64(int fd)
{
	uint64_t v;
	ssize_t n = read(fd, &v, sizeof v);
	return n == 8 ? (long long)v : -1;
}

static long write_u64(int fd, uint64_t v)
{
	return write(fd, &v, sizeof v);
}

static short revents(int fd, short events)
{
	struct pollfd p = { .fd = fd, .events = events };
	return poll(&p, 1, 0) == 1 ? p.revents : 0;
}

static void eventfds(void)
{
	int fd = eventfd(3, 0);
	check_ok("eventfd", fd);
	check_eq("no O_NONBLOCK without EFD_NONBLOCK", 0, fcntl(fd, F_GETFL) & O_NONBLOCK);
	check_eq("no close-on-exec without EFD_CLOEXEC", 0, fcntl(fd, F_GETFD));
	check_eq("read gives the initial value", 3, read_u64(fd));
	check_eq("write adds", 8, write_u64(fd, 5));
	write_u64(fd, 2);
	check_eq("read gives the sum", 7, read_u64(fd));
	check_eq("an empty counter is writable only", POLLOUT, revents(fd, POLLIN | POLLOUT));
	write_u64(fd, 1);
	check_eq("a counter above 0 is readable", POLLIN | POLLOUT,
		 revents(fd, POLLIN | POLLOUT));
	uint32_t small = 1;
	check_errno("a read of 4 bytes EINVAL", read(fd, &small, sizeof small), EINVAL);
	check_errno("a write of 4 bytes EINVAL", write(fd, &small, sizeof small), EINVAL);
	check_errno("a write of 2^64-1 EINVAL", write_u64(fd, UINT64_MAX), EINVAL);
	char big[16] = { 0 };
	check_eq("a read of 16 bytes reads 8", 8, read(fd, big, sizeof big));
	close(fd);

	fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	check("EFD_NONBLOCK sets O_NONBLOCK", (fcntl(fd, F_GETFL) & O_NONBLOCK) != 0,
	      "expected O_NONBLOCK");
	check_eq("EFD_CLOEXEC sets close-on-exec", FD_CLOEXEC, fcntl(fd, F_GETFD));
	check_errno("reading 0 without waiting EAGAIN", read_u64(fd), EAGAIN);
	check_eq("a write up to 2^64-2", 8, write_u64(fd, UINT64_MAX - 1));
	check_eq("a full counter is readable only", POLLIN, revents(fd, POLLIN | POLLOUT));
	check_errno("a write past 2^64-2 without waiting EAGAIN", write_u64(fd, 1), EAGAIN);
	check("the full value reads back", (uint64_t)read_u64(fd) == UINT64_MAX - 1,
	      "expected 2^64-2");
	fcntl(fd, F_SETFL, 0);
	check_eq("F_SETFL clears O_NONBLOCK", 0, fcntl(fd, F_GETFL) & O_NONBLOCK);
	close(fd);

	fd = eventfd(3, EFD_SEMAPHORE | EFD_NONBLOCK);
	long long a = read_u64(fd), b = read_u64(fd), c = read_u64(fd);
	check("EFD_SEMAPHORE reads 1 at a time", a == 1 && b == 1 && c == 1,
	      "expected 1 1 1 got %lld %lld %lld", a, b, c);
	check_errno("EFD_SEMAPHORE at 0 EAGAIN", read_u64(fd), EAGAIN);
	close(fd);
	check_errno("eventfd2 with an unknown flag EINVAL", syscall(SYS_eventfd2, 0, 0x40000000),
		    EINVAL);
	fd = syscall(SYS_eventfd, 9);
	check_eq("eventfd (the old call) reads its value", 9, read_u64(fd));
	close(fd);

	/* A read that waits until another process writes. */
	fd = eventfd(0, 0);
	int pid = fork();
	if (pid == 0) {
		struct timespec t = span(20 * MS);
		nanosleep(&t, NULL);
		write_u64(fd, 42);
		_exit(0);
	}
	check_eq("a blocking read waits for a write", 42, read_u64(fd));
	check_status("the writer", wait_for(pid), 0, 0);
	close(fd);
}

static void timerfds(void)
{
	int fd = timerfd_create(CLOCK_MONOTONIC, 0);
	check_ok("timerfd_create CLOCK_MONOTONIC", fd);
	check_errno("timerfd_create with a bad clock EINVAL", timerfd_create(99, 0), EINVAL);
	check_errno("timerfd_create with a bad flag EINVAL", timerfd_create(CLOCK_MONOTONIC, 1),
		    EINVAL);
	struct itimerspec its = { 0 }, cur;
	check_eq("timerfd_gettime", 0, timerfd_gettime(fd, &cur));
	check("a new timer is disarmed", ns_of(cur.it_value) == 0 && ns_of(cur.it_interval) == 0,
	      "expected zeros");
	/* A second: however slow the system, gettime comes before it ends. */
	its.it_value = span(1000 * MS);
	check_eq("timerfd_settime one-shot 1 s", 0, timerfd_settime(fd, 0, &its, NULL));
	timerfd_gettime(fd, &cur);
	check("gettime shows the time left", ns_of(cur.it_value) > 0 &&
						      ns_of(cur.it_value) <= 1000 * MS &&
						      ns_of(cur.it_interval) == 0,
	      "expected 0 < left <= 1 s");
	its.it_value = span(20 * MS);
	check_eq("timerfd_settime one-shot 20 ms", 0, timerfd_settime(fd, 0, &its, NULL));
	check_eq("a blocking read counts the one expiration", 1, read_u64(fd));
	timerfd_gettime(fd, &cur);
	check_eq("an expired one-shot timer is disarmed", 0, ns_of(cur.it_value));
	fcntl(fd, F_SETFL, O_NONBLOCK);
	check_errno("no expiration since the read EAGAIN", read_u64(fd), EAGAIN);

	its.it_value = span(10 * MS);
	its.it_interval = span(10 * MS);
	timerfd_settime(fd, 0, &its, NULL);
	struct timespec sleep = span(55 * MS);
	nanosleep(&sleep, NULL);
	long long n = read_u64(fd);
	check("an interval timer counts every expiration (>= 5 in 55 ms)", n >= 5,
	      "expected >= 5 got %lld", n);
	timerfd_gettime(fd, &cur);
	check_eq("gettime shows the interval", 10 * MS, ns_of(cur.it_interval));
	fcntl(fd, F_SETFL, 0);
	n = read_u64(fd);
	check("an interval timer re-arms (a blocking read gets >= 1)", n >= 1,
	      "expected >= 1 got %lld", n);
	struct pollfd p = { .fd = fd, .events = POLLIN };
	check_eq("poll waits for the next expiration", 1, poll(&p, 1, -1));
	check_eq("poll says POLLIN", POLLIN, p.revents);
	struct itimerspec old;
	its.it_value = span(1000 * MS);
	its.it_interval = span(0);
	check_eq("settime with the old value", 0, timerfd_settime(fd, 0, &its, &old));
	check_eq("the old interval", 10 * MS, ns_of(old.it_interval));
	timerfd_settime(fd, 0, &its, &old);
	check("the old value is the time left", ns_of(old.it_value) > 0 &&
							ns_of(old.it_value) <= 1000 * MS,
	      "expected 0 < left <= 1 s");
	memset(&its, 0, sizeof its);
	timerfd_settime(fd, 0, &its, NULL);
	timerfd_gettime(fd, &cur);
	check_eq("a zero value disarms", 0, ns_of(cur.it_value));

	its.it_value = span(now_ns(CLOCK_MONOTONIC) + 20 * MS);
	check_eq("TFD_TIMER_ABSTIME on CLOCK_MONOTONIC", 0,
		 timerfd_settime(fd, TFD_TIMER_ABSTIME, &its, NULL));
	check_eq("an absolute monotonic time expires once", 1, read_u64(fd));
	/* 1 ns after the clock's start: passed on any system (the guest's clock may be
	 * younger than a second). */
	its.it_value = span(1);
	check_eq("TFD_TIMER_ABSTIME with a time passed", 0,
		 timerfd_settime(fd, TFD_TIMER_ABSTIME, &its, NULL));
	check_eq("an absolute time passed already expires at once", 1, read_u64(fd));

	its.it_value.tv_nsec = 1000000000;
	check_errno("a bad tv_nsec EINVAL", timerfd_settime(fd, 0, &its, NULL), EINVAL);
	its.it_value = span(MS);
	check_errno("settime with a bad flag EINVAL", timerfd_settime(fd, 4, &its, NULL), EINVAL);
	uint32_t small;
	check_errno("a read of 4 bytes EINVAL", read(fd, &small, sizeof small), EINVAL);
	check_errno("a write EINVAL", write_u64(fd, 1), EINVAL);
	close(fd);
	check_errno("settime of a closed descriptor EBADF", timerfd_settime(fd, 0, &its, NULL),
		    EBADF);
	int efd = eventfd(0, 0);
	check_errno("settime of an eventfd EINVAL", timerfd_settime(efd, 0, &its, NULL), EINVAL);
	check_errno("gettime of an eventfd EINVAL", timerfd_gettime(efd, &cur), EINVAL);
	close(efd);

	fd = timerfd_create(CLOCK_REALTIME, TFD_NONBLOCK | TFD_CLOEXEC);
	check_ok("timerfd_create CLOCK_REALTIME TFD_NONBLOCK|TFD_CLOEXEC", fd);
	check_eq("TFD_CLOEXEC sets close-on-exec", FD_CLOEXEC, fcntl(fd, F_GETFD));
	check_errno("a disarmed timer reads EAGAIN", read_u64(fd), EAGAIN);
	its.it_value = span(now_ns(CLOCK_REALTIME) + 20 * MS);
	its.it_interval = span(0);
	timerfd_settime(fd, TFD_TIMER_ABSTIME, &its, NULL);
	p.fd = fd;
	check_eq("poll waits for an absolute real-time expiry", 1, poll(&p, 1, -1));
	check_eq("the real-time timer expired once", 1, read_u64(fd));
	close(fd);
	fd = timerfd_create(CLOCK_BOOTTIME, 0);
	check_ok("timerfd_create CLOCK_BOOTTIME", fd);
	close(fd);
}

static int alarmed;
static void on_alarm(int sig)
{
	(void)sig;
	alarmed = 1;
}

static void epolls(void)
{
	struct epoll_event ev, out[8];
	check_errno("epoll_create(0) EINVAL", epoll_create(0), EINVAL);
	int ep = epoll_create(1);
	check_ok("epoll_create(1)", ep);
	check_eq("epoll_create's descriptor is not close-on-exec", 0, fcntl(ep, F_GETFD));
	int ep2 = epoll_create1(EPOLL_CLOEXEC);
	check_eq("EPOLL_CLOEXEC sets close-on-exec", FD_CLOEXEC, fcntl(ep2, F_GETFD));
	check_errno("epoll_create1 with a bad flag EINVAL", epoll_create1(1), EINVAL);
	check("struct epoll_event is 12 bytes", sizeof ev == 12, "expected 12 got %zu",
	      sizeof ev);

	int p[2];
	pipe2(p, O_NONBLOCK);
	ev.events = EPOLLIN;
	ev.data.u64 = 0x1122334455667788ULL;
	check_eq("EPOLL_CTL_ADD a pipe's read end", 0, epoll_ctl(ep, EPOLL_CTL_ADD, p[0], &ev));
	check_eq("nothing ready: timeout 0 gives 0", 0, epoll_wait(ep, out, 8, 0));
	write(p[1], "x", 1);
	int n = epoll_wait(ep, out, 8, 0);
	check_eq("data makes it ready", 1, n);
	check("the report has EPOLLIN and the data word",
	      n == 1 && out[0].events == EPOLLIN && out[0].data.u64 == 0x1122334455667788ULL,
	      "expected EPOLLIN 0x1122334455667788");
	check_eq("level-triggered: ready again while the data is there", 1,
		 epoll_wait(ep, out, 8, 0));
	check_errno("ADD twice EEXIST", epoll_ctl(ep, EPOLL_CTL_ADD, p[0], &ev), EEXIST);
	check_errno("MOD of a descriptor not added ENOENT", epoll_ctl(ep, EPOLL_CTL_MOD, p[1], &ev),
		    ENOENT);
	check_errno("DEL of a descriptor not added ENOENT",
		    epoll_ctl(ep, EPOLL_CTL_DEL, p[1], NULL), ENOENT);
	check_errno("a closed descriptor EBADF", epoll_ctl(ep, EPOLL_CTL_ADD, 999, &ev), EBADF);
	check_errno("a closed epoll descriptor EBADF", epoll_ctl(999, EPOLL_CTL_ADD, p[0], &ev),
		    EBADF);
	check_errno("an epfd that is no epoll EINVAL", epoll_ctl(p[1], EPOLL_CTL_ADD, p[0], &ev),
		    EINVAL);
	check_errno("an epoll descriptor in itself EINVAL", epoll_ctl(ep, EPOLL_CTL_ADD, ep, &ev),
		    EINVAL);
	check_errno("an unknown op EINVAL", epoll_ctl(ep, 99, p[1], &ev), EINVAL);
	int file = open(self_path, O_RDONLY);
	check_errno("a regular file EPERM", epoll_ctl(ep, EPOLL_CTL_ADD, file, &ev), EPERM);
	close(file);
	check_errno("maxevents 0 EINVAL", epoll_wait(ep, out, 0, 0), EINVAL);
	check_errno("maxevents -1 EINVAL", syscall(SYS_epoll_wait, ep, out, -1, 0), EINVAL);
	check_errno("epoll_wait on a pipe EINVAL", epoll_wait(p[0], out, 8, 0), EINVAL);
	check_errno("epoll_wait on a closed descriptor EBADF", epoll_wait(999, out, 8, 0), EBADF);
	check_eq("poll of an epoll descriptor with a ready item", POLLIN, revents(ep, POLLIN));

	ev.events = EPOLLOUT;
	ev.data.u64 = 2;
	check_eq("ADD the write end for EPOLLOUT", 0, epoll_ctl(ep, EPOLL_CTL_ADD, p[1], &ev));
	n = epoll_wait(ep, out, 8, 0);
	check_eq("both ends ready", 2, n);
	n = epoll_wait(ep, out, 1, 0);
	check_eq("maxevents 1 gives one", 1, n);
	check_eq("EPOLL_CTL_DEL", 0, epoll_ctl(ep, EPOLL_CTL_DEL, p[1], NULL));
	check_eq("one left after DEL", 1, epoll_wait(ep, out, 8, 0));
	ev.events = EPOLLIN;
	ev.data.u64 = 3;
	check_eq("EPOLL_CTL_MOD", 0, epoll_ctl(ep, EPOLL_CTL_MOD, p[0], &ev));
	n = epoll_wait(ep, out, 8, 0);
	check("MOD changes the data word", n == 1 && out[0].data.u64 == 3, "expected 3");
	char buf[16];
	read(p[0], buf, sizeof buf);
	check_eq("drained: nothing ready", 0, epoll_wait(ep, out, 8, 0));
	close(p[1]);
	n = epoll_wait(ep, out, 8, 0);
	check("a pipe without writers reports EPOLLHUP unasked",
	      n == 1 && (out[0].events & EPOLLHUP) != 0, "expected EPOLLHUP");
	close(p[0]);
	check_eq("a closed descriptor leaves the interest list", 0, epoll_wait(ep, out, 8, 0));

	/* Edge-triggered. */
	pipe2(p, O_NONBLOCK);
	ev.events = EPOLLIN | EPOLLET;
	ev.data.u64 = 4;
	epoll_ctl(ep, EPOLL_CTL_ADD, p[0], &ev);
	check_eq("EPOLLET: nothing before data", 0, epoll_wait(ep, out, 8, 0));
	write(p[1], "ab", 2);
	check_eq("EPOLLET: data reported once", 1, epoll_wait(ep, out, 8, 0));
	check_eq("EPOLLET: not again while unread", 0, epoll_wait(ep, out, 8, 0));
	while (read(p[0], buf, 1) == 1)
		;
	write(p[1], "c", 1);
	check_eq("EPOLLET: new data after draining reported", 1, epoll_wait(ep, out, 8, 0));
	fcntl(p[0], F_SETFL, 0);
	check_eq("DEL after F_SETFL changed O_NONBLOCK", 0,
		 epoll_ctl(ep, EPOLL_CTL_DEL, p[0], NULL));
	fcntl(p[0], F_SETFL, O_NONBLOCK);

	/* One-shot. */
	ev.events = EPOLLIN | EPOLLONESHOT;
	ev.data.u64 = 5;
	epoll_ctl(ep, EPOLL_CTL_ADD, p[0], &ev);
	check_eq("EPOLLONESHOT: reported once", 1, epoll_wait(ep, out, 8, 0));
	check_eq("EPOLLONESHOT: then disabled", 0, epoll_wait(ep, out, 8, 0));
	check_errno("EPOLLONESHOT: still in the list (ADD EEXIST)",
		    epoll_ctl(ep, EPOLL_CTL_ADD, p[0], &ev), EEXIST);
	epoll_ctl(ep, EPOLL_CTL_MOD, p[0], &ev);
	check_eq("EPOLLONESHOT: MOD re-arms", 1, epoll_wait(ep, out, 8, 0));
	ev.events = EPOLLIN;
	epoll_ctl(ep, EPOLL_CTL_MOD, p[0], &ev);
	int dup_fd = dup(p[0]);
	close(p[0]);
	check_eq("a descriptor closed while a dup is open stays in the list", 1,
		 epoll_wait(ep, out, 8, 0));
	close(dup_fd);
	check_eq("the last descriptor closed: it left the list", 0, epoll_wait(ep, out, 8, 0));
	close(p[1]);

	/* A timeout, a timer and an eventfd. */
	long long t0 = now_ns(CLOCK_MONOTONIC);
	check_eq("a 30 ms timeout with nothing ready gives 0", 0, epoll_wait(ep, out, 8, 30));
	check("it waited at least 30 ms", now_ns(CLOCK_MONOTONIC) - t0 >= 30 * MS,
	      "expected >= 30 ms");
	int tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK);
	ev.events = EPOLLIN;
	ev.data.u64 = 6;
	epoll_ctl(ep, EPOLL_CTL_ADD, tfd, &ev);
	struct itimerspec its = { .it_value = span(20 * MS) };
	timerfd_settime(tfd, 0, &its, NULL);
	n = epoll_wait(ep, out, 8, -1);
	check("epoll_wait wakes up when a timer expires", n == 1 && out[0].data.u64 == 6,
	      "expected the timer's report");
	check_eq("the timer expired once", 1, read_u64(tfd));
	check_eq("a read timer is not ready", 0, epoll_wait(ep, out, 8, 0));
	epoll_ctl(ep, EPOLL_CTL_DEL, tfd, NULL);
	int efd = eventfd(0, EFD_NONBLOCK);
	ev.events = EPOLLIN;
	ev.data.u64 = 7;
	epoll_ctl(ep, EPOLL_CTL_ADD, efd, &ev);
	check_eq("an eventfd at 0 is not readable", 0, epoll_wait(ep, out, 8, 0));
	write_u64(efd, 1);
	n = epoll_wait(ep, out, 8, 0);
	check("an eventfd above 0 reports EPOLLIN only (EPOLLOUT not asked)",
	      n == 1 && out[0].events == EPOLLIN && out[0].data.u64 == 7, "expected EPOLLIN 7");
	read_u64(efd);

	/* A wait another process ends. */
	int pid = fork();
	if (pid == 0) {
		struct timespec t = span(20 * MS);
		nanosleep(&t, NULL);
		write_u64(efd, 5);
		_exit(0);
	}
	n = epoll_wait(ep, out, 8, -1);
	check("epoll_wait wakes up when another process writes", n == 1 && out[0].data.u64 == 7,
	      "expected the eventfd's report");
	check_status("the writer", wait_for(pid), 0, 0);
	check_eq("epoll_pwait with a mask", 1, epoll_pwait(ep, out, 8, 0, &(sigset_t){ 0 }));
	read_u64(efd);

	/* Nesting. */
	ev.events = EPOLLIN;
	ev.data.u64 = 8;
	check_eq("an epoll descriptor in another", 0, epoll_ctl(ep2, EPOLL_CTL_ADD, ep, &ev));
	check_errno("a loop of epoll descriptors ELOOP", epoll_ctl(ep, EPOLL_CTL_ADD, ep2, &ev),
		    ELOOP);
	check_eq("the outer one is not ready while the inner one is not", 0,
		 epoll_wait(ep2, out, 8, 0));
	write_u64(efd, 1);
	n = epoll_wait(ep2, out, 8, 0);
	check("the outer one reports the inner one ready", n == 1 && out[0].data.u64 == 8,
	      "expected the inner epoll's report");
	read_u64(efd);

	/* A signal interrupts a wait: SIGALRM is blocked but during the wait, so it cannot
	 * come before the wait began. */
	struct sigaction sa = { .sa_handler = on_alarm };
	sigaction(SIGALRM, &sa, NULL);
	sigset_t block, none;
	sigemptyset(&block);
	sigaddset(&block, SIGALRM);
	sigemptyset(&none);
	sigprocmask(SIG_BLOCK, &block, NULL);
	struct itimerval it = { .it_value = { .tv_usec = 20000 } };
	setitimer(ITIMER_REAL, &it, NULL);
	check_errno("a signal epoll_pwait unblocks interrupts it EINTR",
		    epoll_pwait(ep, out, 8, -1, &none), EINTR);
	check_eq("the handler ran", 1, alarmed);
	sigprocmask(SIG_UNBLOCK, &block, NULL);
	alarmed = 0;
	setitimer(ITIMER_REAL, &it, NULL);
	check_eq("epoll_pwait blocking SIGALRM times out instead", 0,
		 epoll_pwait(ep, out, 8, 60, &block));
	check_eq("the handler ran after the wait", 1, alarmed);
	signal(SIGALRM, SIG_DFL);
	close(efd);
	close(tfd);
	close(ep2);
	close(ep);
}

void area_events(void)
{
	eventfds();
	timerfds();
	epolls();
}
