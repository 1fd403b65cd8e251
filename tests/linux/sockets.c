/* Area `sockets`: AF_INET TCP and UDP on the loopback (127.0.0.1): socket, bind (port 0
 * picks one; EADDRINUSE), listen with a backlog, accept/accept4, connect (blocking;
 * non-blocking with EINPROGRESS, poll and SO_ERROR; ECONNREFUSED), read/write,
 * send/recv, sendto/recvfrom, sendmsg/recvmsg, a 256 KiB transfer between two processes,
 * shutdown, getsockname/getpeername, setsockopt/getsockopt, O_NONBLOCK's EAGAIN, poll and
 * select, sendfile from a file, fstat, and the errors of calls on the wrong socket or on
 * no socket at all; a thread waiting in a read of a socket until another thread's peer
 * writes; a connected AF_UNIX stream pair (socketpair) both ways, across a fork, shut down
 * and closed. Ports are the ones bind picks, so that it runs beside anything. */
#include "check.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/select.h>
#include <sys/sendfile.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <sys/un.h>
#include <sys/wait.h>

#define BIG (256 * 1024)

static struct sockaddr_in loopback(int port)
{
	struct sockaddr_in a;
	memset(&a, 0, sizeof a);
	a.sin_family = AF_INET;
	a.sin_port = htons(port);
	a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
	return a;
}

/* A TCP socket listening on 127.0.0.1 at a port bind picked; its port in *port. */
static int listener(int backlog, int *port)
{
	int fd = socket(AF_INET, SOCK_STREAM, 0);
	struct sockaddr_in a = loopback(0);
	socklen_t len = sizeof a;
	if (fd < 0 || bind(fd, (struct sockaddr *)&a, sizeof a) != 0 || listen(fd, backlog) != 0 ||
	    getsockname(fd, (struct sockaddr *)&a, &len) != 0)
		return -1;
	*port = ntohs(a.sin_port);
	return fd;
}

/* A blocking TCP connection to 127.0.0.1:port (-1 with errno on failure). */
static int connected(int port)
{
	int fd = socket(AF_INET, SOCK_STREAM, 0);
	struct sockaddr_in a = loopback(port);
	if (fd < 0)
		return -1;
	if (connect(fd, (struct sockaddr *)&a, sizeof a) != 0) {
		int e = errno;
		close(fd);
		errno = e;
		return -1;
	}
	return fd;
}

/* Reads exactly n bytes (fewer at end of file). */
static long read_full(int fd, char *buf, long n)
{
	long got = 0, r;
	while (got < n && (r = read(fd, buf + got, n - got)) > 0)
		got += r;
	return got;
}

static void tcp(void)
{
	int port;
	int l = listener(4, &port);
	check("listen on 127.0.0.1 at a picked port", l >= 0 && port > 0, "expected a port");
	int c = connected(port);
	check_ok("connect to the listener", c);
	struct sockaddr_in peer, mine;
	socklen_t len = sizeof peer;
	int s = accept(l, (struct sockaddr *)&peer, &len);
	check_ok("accept", s);
	check_eq("accept's address length", sizeof peer, len);
	len = sizeof mine;
	getsockname(c, (struct sockaddr *)&mine, &len);
	check("accept names the client's address",
	      peer.sin_family == AF_INET && peer.sin_port == mine.sin_port &&
		      peer.sin_addr.s_addr == htonl(INADDR_LOOPBACK),
	      "expected 127.0.0.1 and the client's port");
	len = sizeof peer;
	check_eq("getpeername of the client", 0, getpeername(c, (struct sockaddr *)&peer, &len));
	check_eq("the client's peer is the listener's port", port, ntohs(peer.sin_port));
	len = sizeof mine;
	getsockname(s, (struct sockaddr *)&mine, &len);
	check_eq("the accepted socket has the listener's port", port, ntohs(mine.sin_port));
	check("the accepted socket's address is 127.0.0.1",
	      mine.sin_addr.s_addr == htonl(INADDR_LOOPBACK), "expected 127.0.0.1");

	char buf[64];
	check_eq("write to the connection", 5, write(c, "hello", 5));
	check_eq("read what the client wrote", 5, read_full(s, buf, 5));
	check("the bytes arrive", memcmp(buf, "hello", 5) == 0, "expected hello");
	check_eq("send back", 3, send(s, "abc", 3, 0));
	check_eq("recv", 3, recv(c, buf, sizeof buf, 0));
	check("the bytes come back", memcmp(buf, "abc", 3) == 0, "expected abc");

	/* Non-blocking reads. */
	check_eq("F_SETFL O_NONBLOCK on a socket", 0, fcntl(c, F_SETFL, O_NONBLOCK));
	check("F_GETFL says O_NONBLOCK", (fcntl(c, F_GETFL) & O_NONBLOCK) != 0, "expected it");
	check_errno("read of an empty non-blocking socket EAGAIN", read(c, buf, 1), EAGAIN);
	check_errno("recv MSG_DONTWAIT of an empty socket EAGAIN",
		    recv(s, buf, 1, MSG_DONTWAIT), EAGAIN);
	fcntl(c, F_SETFL, 0);

	/* poll and select see data arrive. */
	struct pollfd p = { .fd = s, .events = POLLIN };
	check_eq("poll of an idle connection times out", 0, poll(&p, 1, 10));
	write(c, "x", 1);
	check_eq("poll sees the byte", 1, poll(&p, 1, 1000));
	check("POLLIN", (p.revents & POLLIN) != 0, "expected POLLIN");
	fd_set r;
	FD_ZERO(&r);
	FD_SET(s, &r);
	struct timeval tv = { 1, 0 };
	check_eq("select sees it too", 1, select(s + 1, &r, NULL, NULL, &tv));
	read(s, buf, 1);
	p.fd = c;
	p.events = POLLOUT;
	check_eq("a connection with room is writable", 1, poll(&p, 1, 0));

	/* sendmsg and recvmsg gather and scatter. */
	struct iovec out[2] = { { "sc", 2 }, { "atter", 5 } };
	struct msghdr m = { .msg_iov = out, .msg_iovlen = 2 };
	check_eq("sendmsg of two pieces", 7, sendmsg(c, &m, 0));
	char a[3] = { 0 }, b[8] = { 0 };
	struct iovec in[2] = { { a, 3 }, { b, 4 } };
	struct msghdr mi = { .msg_iov = in, .msg_iovlen = 2 };
	check_eq("recvmsg into two pieces", 7, recvmsg(s, &mi, MSG_WAITALL));
	check("the pieces hold the message", memcmp(a, "sca", 3) == 0 && memcmp(b, "tter", 4) == 0,
	      "expected sca|tter");

	/* shutdown: the peer reads end of file, writing afterwards is EPIPE. */
	check_eq("shutdown SHUT_WR", 0, shutdown(c, SHUT_WR));
	check_eq("the peer reads end of file", 0, read(s, buf, sizeof buf));
	signal(SIGPIPE, SIG_IGN);
	check_errno("write after SHUT_WR EPIPE", write(c, "x", 1), EPIPE);
	signal(SIGPIPE, SIG_DFL);
	check_eq("the other way still works", 2, write(s, "ok", 2));
	check_eq("and is read", 2, read_full(c, buf, 2));
	close(s);
	check_eq("end of file once the peer closed", 0, read(c, buf, sizeof buf));
	close(c);

	/* A child sends 256 KiB; the parent reads it all in order. */
	int pid = fork();
	if (pid == 0) {
		close(l);
		int fd = connected(port);
		char *data = malloc(BIG);
		if (fd < 0 || !data)
			_exit(2);
		for (int i = 0; i < BIG; i++)
			data[i] = (char)(i * 7);
		long w = write(fd, data, BIG);
		_exit(w == BIG ? 0 : 3);
	}
	s = accept(l, NULL, NULL);
	char *big = malloc(BIG);
	long got = read_full(s, big, BIG);
	int in_order = 1;
	for (long i = 0; i < got; i++)
		in_order &= big[i] == (char)(i * 7);
	check_eq("the reader gets all 256 KiB", BIG, got);
	check_eq("in order", 1, in_order);
	check_eq("then end of file", 0, read(s, big, 1));
	check_status("a blocking write of 256 KiB returns its whole count", wait_for(pid), 0, 0);
	free(big);
	close(s);

	/* Ping-pong between two processes. */
	pid = fork();
	if (pid == 0) {
		close(l);
		int fd = connected(port);
		char ch;
		while (read(fd, &ch, 1) == 1) {
			ch++;
			write(fd, &ch, 1);
		}
		_exit(0);
	}
	s = accept(l, NULL, NULL);
	int rounds_ok = 1;
	for (int i = 0; i < 100; i++) {
		char sent = (char)i, ch = 0;
		rounds_ok &= write(s, &sent, 1) == 1 && read(s, &ch, 1) == 1 && ch == (char)(i + 1);
	}
	check_eq("100 round trips over a connection", 1, rounds_ok);
	close(s);
	check_status("the echo child ends at end of file", wait_for(pid), 0, 0);
	close(l);
}

static void backlog_and_nonblocking(void)
{
	int port;
	int l = listener(3, &port);
	/* A listener with nothing waiting. */
	fcntl(l, F_SETFL, O_NONBLOCK);
	check_errno("accept on an idle non-blocking listener EAGAIN", accept(l, NULL, NULL), EAGAIN);
	fcntl(l, F_SETFL, 0);

	/* Three connections wait in the backlog until accepted, in order. */
	int c[3], ok = 1;
	for (int i = 0; i < 3; i++) {
		c[i] = connected(port);
		ok &= c[i] >= 0 && write(c[i], "0123456789" + i, 1) == 1;
	}
	check_eq("three connections complete before any accept", 1, ok);
	struct pollfd p = { .fd = l, .events = POLLIN };
	check_eq("the listener polls readable", 1, poll(&p, 1, 1000));
	int firsts = 0;
	for (int i = 0; i < 3; i++) {
		int s = accept4(l, NULL, NULL, SOCK_CLOEXEC | SOCK_NONBLOCK);
		char ch = 0;
		struct pollfd q = { .fd = s, .events = POLLIN };
		poll(&q, 1, 1000);
		if (s >= 0 && read(s, &ch, 1) == 1)
			firsts |= 1 << (ch - '0');
		if (i == 0) {
			check("accept4 SOCK_CLOEXEC", fcntl(s, F_GETFD) == FD_CLOEXEC,
			      "expected FD_CLOEXEC");
			check("accept4 SOCK_NONBLOCK", (fcntl(s, F_GETFL) & O_NONBLOCK) != 0,
			      "expected O_NONBLOCK");
		}
		close(s);
	}
	check_eq("each waiting connection is accepted once", 7, firsts);
	for (int i = 0; i < 3; i++)
		close(c[i]);

	/* A non-blocking connect: EINPROGRESS (or at once), then writable, SO_ERROR 0. */
	int fd = socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK, 0);
	struct sockaddr_in a = loopback(port);
	int r = connect(fd, (struct sockaddr *)&a, sizeof a);
	check("a non-blocking connect starts", r == 0 || errno == EINPROGRESS,
	      "expected 0 or EINPROGRESS got %s", errno_name(errno));
	p.fd = fd;
	p.events = POLLOUT;
	check_eq("it polls writable once connected", 1, poll(&p, 1, 2000));
	int err = -1;
	socklen_t len = sizeof err;
	getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
	check_eq("SO_ERROR 0", 0, err);
	int s = accept(l, NULL, NULL);
	check_ok("the listener accepts it", s);
	close(s);
	close(fd);

	/* A port nobody listens on: refused, blocking or not. */
	close(l);
	errno = 0;
	check_errno("connect to a closed port ECONNREFUSED", connected(port), ECONNREFUSED);
	fd = socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK, 0);
	r = connect(fd, (struct sockaddr *)&a, sizeof a);
	if (r == -1 && errno == EINPROGRESS) {
		p.fd = fd;
		p.events = POLLOUT;
		poll(&p, 1, 2000);
		err = 0;
		len = sizeof err;
		getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
	} else {
		err = r == -1 ? errno : 0;
	}
	check_eq("a non-blocking connect to it fails with ECONNREFUSED", ECONNREFUSED, err);
	close(fd);
}

static void udp(void)
{
	int u1 = socket(AF_INET, SOCK_DGRAM, 0), u2 = socket(AF_INET, SOCK_DGRAM, 0);
	struct sockaddr_in a1 = loopback(0), a2 = loopback(0);
	socklen_t len = sizeof a1;
	check_eq("bind a UDP socket", 0, bind(u1, (struct sockaddr *)&a1, sizeof a1));
	getsockname(u1, (struct sockaddr *)&a1, &len);
	bind(u2, (struct sockaddr *)&a2, sizeof a2);
	len = sizeof a2;
	getsockname(u2, (struct sockaddr *)&a2, &len);
	check_eq("sendto", 4, sendto(u2, "ping", 4, 0, (struct sockaddr *)&a1, sizeof a1));
	char buf[64];
	struct sockaddr_in from;
	len = sizeof from;
	check_eq("recvfrom", 4, recvfrom(u1, buf, sizeof buf, 0, (struct sockaddr *)&from, &len));
	check("recvfrom names the sender",
	      from.sin_port == a2.sin_port && from.sin_addr.s_addr == htonl(INADDR_LOOPBACK),
	      "expected the sender's port");
	check("the datagram", memcmp(buf, "ping", 4) == 0, "expected ping");
	sendto(u2, "abcdefgh", 8, 0, (struct sockaddr *)&a1, sizeof a1);
	sendto(u2, "second", 6, 0, (struct sockaddr *)&a1, sizeof a1);
	check_eq("a datagram longer than the buffer is cut", 3, recv(u1, buf, 3, 0));
	check_eq("the rest of it is gone", 6, recv(u1, buf, sizeof buf, 0));
	check("datagrams keep their bounds", memcmp(buf, "second", 6) == 0, "expected second");
	check_errno("recv of an empty socket MSG_DONTWAIT EAGAIN", recv(u1, buf, 1, MSG_DONTWAIT),
		    EAGAIN);
	check_eq("connect a UDP socket", 0, connect(u1, (struct sockaddr *)&a2, sizeof a2));
	check_eq("send on it", 4, send(u1, "pong", 4, 0));
	check_eq("the other reads it", 4, read(u2, buf, sizeof buf));
	len = sizeof from;
	check_eq("getpeername of a connected UDP socket", 0,
		 getpeername(u1, (struct sockaddr *)&from, &len));
	check_eq("its peer", ntohs(a2.sin_port), ntohs(from.sin_port));
	check_errno("send without an address EDESTADDRREQ", send(u2, "x", 1, 0), EDESTADDRREQ);
	struct pollfd p = { .fd = u2, .events = POLLIN | POLLOUT };
	check_eq("an idle UDP socket polls writable", 1, poll(&p, 1, 0));
	check_eq("and only writable", POLLOUT, p.revents);
	close(u1);
	close(u2);
}

static void options_and_errors(void)
{
	int fd = socket(AF_INET, SOCK_STREAM, 0);
	int on = 1, v = -1;
	socklen_t len = sizeof v;
	check_eq("SO_REUSEADDR", 0, setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on));
	getsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &v, &len);
	check_eq("getsockopt SO_REUSEADDR", 1, v != 0);
	check_eq("SO_KEEPALIVE", 0, setsockopt(fd, SOL_SOCKET, SO_KEEPALIVE, &on, sizeof on));
	len = sizeof v;
	getsockopt(fd, SOL_SOCKET, SO_KEEPALIVE, &v, &len);
	check_eq("getsockopt SO_KEEPALIVE", 1, v != 0);
	check_eq("TCP_NODELAY", 0, setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &on, sizeof on));
	len = sizeof v;
	getsockopt(fd, SOL_SOCKET, SO_TYPE, &v, &len);
	check_eq("SO_TYPE", SOCK_STREAM, v);
	check_eq("its length", sizeof v, len);
	check_errno("an option of a short length EINVAL",
		    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, 1), EINVAL);
	struct stat st;
	check("fstat says socket", fstat(fd, &st) == 0 && S_ISSOCK(st.st_mode), "expected S_IFSOCK");
	char buf[4];
	check_errno("read of an unconnected socket ENOTCONN", read(fd, buf, 1), ENOTCONN);
	struct sockaddr_in a;
	len = sizeof a;
	check_errno("getpeername unconnected ENOTCONN", getpeername(fd, (struct sockaddr *)&a, &len),
		    ENOTCONN);
	check_errno("shutdown unconnected ENOTCONN", shutdown(fd, SHUT_RDWR), ENOTCONN);
	check_errno("accept without listen EINVAL", accept(fd, NULL, NULL), EINVAL);

	/* A port in use. */
	int port;
	int l = listener(1, &port);
	a = loopback(port);
	check_errno("bind to a listening port EADDRINUSE",
		    bind(fd, (struct sockaddr *)&a, sizeof a), EADDRINUSE);
	close(fd);
	fd = socket(AF_INET, SOCK_STREAM, 0);
	a.sin_family = AF_INET + 1;
	check("bind of another family fails",
	      bind(fd, (struct sockaddr *)&a, sizeof a) == -1 &&
		      (errno == EAFNOSUPPORT || errno == EINVAL),
	      "expected EAFNOSUPPORT got %s", errno_name(errno));
	a = loopback(0);
	check_errno("bind with a short address EINVAL", bind(fd, (struct sockaddr *)&a, 4), EINVAL);
	close(fd);
	close(l);
	int u = socket(AF_INET, SOCK_DGRAM, 0);
	check_errno("listen on UDP EOPNOTSUPP", listen(u, 1), EOPNOTSUPP);
	close(u);

	/* Families and types there are not. */
	check_errno("socket of an unknown family EAFNOSUPPORT", socket(200, SOCK_STREAM, 0),
		    EAFNOSUPPORT);
	int v6 = socket(AF_INET6, SOCK_STREAM, 0);
	check("AF_INET6 works or is EAFNOSUPPORT", v6 >= 0 || errno == EAFNOSUPPORT,
	      "got %s", errno_name(errno));
	if (v6 >= 0)
		close(v6);
	check_errno("TCP over a datagram socket EPROTONOSUPPORT",
		    socket(AF_INET, SOCK_DGRAM, IPPROTO_TCP), EPROTONOSUPPORT);
	int p[2];
	pipe(p);
	check_errno("bind of a pipe ENOTSOCK", bind(p[0], (struct sockaddr *)&a, sizeof a),
		    ENOTSOCK);
	close(p[0]);
	close(p[1]);
	check_errno("listen on a closed descriptor EBADF", listen(999, 1), EBADF);
}

static void sendfile_to_socket(void)
{
	const char *path = "/tmp/linux-tests-sendfile";
	int f = open(path, O_RDWR | O_CREAT | O_TRUNC, 0600);
	char data[10000];
	for (int i = 0; i < (int)sizeof data; i++)
		data[i] = (char)(i * 3);
	write(f, data, sizeof data);
	int port;
	int l = listener(1, &port);
	int c = connected(port);
	int s = accept(l, NULL, NULL);
	off_t off = 0;
	long sent = 0, n;
	while (sent < (long)sizeof data && (n = sendfile(c, f, &off, sizeof data - sent)) > 0)
		sent += n;
	check_eq("sendfile from a file to a socket", sizeof data, sent);
	check_eq("the offset moved", sizeof data, off);
	char got[sizeof data];
	check_eq("the peer reads it", sizeof data, read_full(s, got, sizeof got));
	check("the file's bytes", memcmp(got, data, sizeof data) == 0, "expected the file");
	close(c);
	close(s);
	close(l);
	close(f);
	unlink(path);
}

static void socket_pair(void)
{
	int sv[2];
	char buf[16];
	check_ok("socketpair AF_UNIX SOCK_STREAM", socketpair(AF_UNIX, SOCK_STREAM, 0, sv));
	check_eq("write at one end", 4, write(sv[0], "ping", 4));
	check_eq("read at the other", 4, read(sv[1], buf, sizeof buf));
	check("the bytes arrive", memcmp(buf, "ping", 4) == 0, "expected ping");
	check_eq("send back", 4, send(sv[1], "pong", 4, 0));
	check_eq("recv", 4, recv(sv[0], buf, sizeof buf, 0));
	check("the bytes come back", memcmp(buf, "pong", 4) == 0, "expected pong");
	int type = 0;
	socklen_t len = sizeof type;
	check_ok("getsockopt SO_TYPE of a pair's end", getsockopt(sv[0], SOL_SOCKET, SO_TYPE, &type, &len));
	check_eq("it is SOCK_STREAM", SOCK_STREAM, type);
	struct stat st;
	check_ok("fstat of a pair's end", fstat(sv[0], &st));
	check("it is a socket", S_ISSOCK(st.st_mode), "expected S_IFSOCK");
	struct sockaddr_un a;
	len = sizeof a;
	check_ok("getsockname of a pair's end", getsockname(sv[0], (struct sockaddr *)&a, &len));
	check_eq("an unnamed address: the family alone", sizeof(sa_family_t), len);
	check_eq("AF_UNIX", AF_UNIX, a.sun_family);
	check_errno("recv MSG_DONTWAIT of an empty end EAGAIN", recv(sv[0], buf, 1, MSG_DONTWAIT), EAGAIN);
	struct pollfd pf = { .fd = sv[1], .events = POLLIN };
	check_eq("poll of an empty end times out", 0, poll(&pf, 1, 0));
	check_eq("write a byte", 1, write(sv[0], "x", 1));
	check_eq("poll sees it", 1, poll(&pf, 1, 0));
	check_eq("POLLIN", POLLIN, pf.revents & POLLIN);
	check_eq("read it", 1, read(sv[1], buf, sizeof buf));
	check_ok("shutdown SHUT_WR of a pair's end", shutdown(sv[0], SHUT_WR));
	check_eq("the peer reads end of file", 0, read(sv[1], buf, sizeof buf));
	check_errno("send after SHUT_WR EPIPE", send(sv[0], "x", 1, MSG_NOSIGNAL), EPIPE);
	check_eq("the other way still carries bytes", 2, write(sv[1], "ok", 2));
	check_eq("and they arrive", 2, read(sv[0], buf, sizeof buf));
	close(sv[1]);
	check_errno("send to a closed peer EPIPE", send(sv[0], "x", 1, MSG_NOSIGNAL), EPIPE);
	close(sv[0]);
	/* Across a fork: the child's end closes with the child. */
	check_ok("socketpair SOCK_CLOEXEC", socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv));
	pid_t child = fork();
	if (child == 0) {
		close(sv[0]);
		write(sv[1], "child", 5);
		_exit(0);
	}
	close(sv[1]);
	check_eq("the child's bytes through the pair", 5, read_full(sv[0], buf, 5));
	int status;
	waitpid(child, &status, 0);
	check_eq("end of file once the child's end closed", 0, read(sv[0], buf, sizeof buf));
	close(sv[0]);
	check_errno("socketpair AF_INET EOPNOTSUPP", socketpair(AF_INET, SOCK_STREAM, 0, sv), EOPNOTSUPP);
}

static int waiting_listener;

static void *accept_and_read(void *unused)
{
	(void)unused;
	char buf[8];
	int fd = accept(waiting_listener, NULL, NULL);
	long got = fd < 0 ? -1 : read(fd, buf, sizeof buf);
	if (got > 0 && write(fd, buf, got) != got)
		got = -1;
	if (fd >= 0)
		close(fd);
	return (void *)got;
}

/* A thread (not the process's first) accepts a connection, then waits in a read of it:
 * the write of the connection's other end, after a while, ends its wait, and the first
 * thread waits in a read of the echo meanwhile. */
static void thread_waits_on_a_socket(void)
{
	int port;
	waiting_listener = listener(1, &port);
	pthread_t t;
	check_eq("a thread to accept and read", 0,
		 pthread_create(&t, NULL, accept_and_read, NULL));
	usleep(20000); /* it waits in its accept meanwhile */
	int c = connected(port);
	check("connect to the thread's listener", c >= 0, "%s", errno_name(errno));
	usleep(20000); /* and then in its read */
	check_eq("the other end writes", 4, write(c, "ping", 4));
	char echo[8];
	check_eq("and reads the thread's echo", 4, read_full(c, echo, 4));
	void *got = NULL;
	check_eq("the thread ends", 0, pthread_join(t, &got));
	check_eq("its read got the bytes", 4, (long)got);
	close(c);
	close(waiting_listener);
}

void area_sockets(void)
{
	tcp();
	backlog_and_nonblocking();
	udp();
	options_and_errors();
	sendfile_to_socket();
	thread_waits_on_a_socket();
	socket_pair();
}
