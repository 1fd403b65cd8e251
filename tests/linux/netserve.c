/* linux-netserve: the guest side of the network benchmark of `cargo xtask bench --net`
 * (xtask/src/netbench.rs times everything from the host; this program only answers).
 * It serves one TCP connection at a time on PORT (default 5001) and echoes UDP datagrams
 * on the same port number (a child process). A TCP connection's first byte says what it
 * is for:
 *
 *   'P'            ping: answers 'p' (the host's readiness probe), then closes
 *   'R'            receive: reads until the peer shuts its side down, in 64 KiB reads, then
 *                  writes the byte count as a decimal line and closes
 *   'S' <4 bytes>  send: writes the little-endian count of 64 KiB blocks, each in one
 *                  64 KiB write, then closes
 *   'E'            echo: 64-byte messages back as they come (TCP_NODELAY) until EOF
 *   'Q'            quit: answers 'q', ends the UDP child and exits 0
 *
 *     linux-netserve [PORT]
 *
 * Prints `netserve: listening on <port>` once both sockets are bound; every error is a line
 * `netserve: error: <what>: <errno text>` (and exit 1 when it cannot serve at all). */
#define _GNU_SOURCE
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#define BLOCK (64 * 1024)
#define MESSAGE 64

static char block[BLOCK];

static void fail(const char *what)
{
	printf("netserve: error: %s: %s\n", what, strerror(errno));
	fflush(stdout);
}

/* Reads exactly `n` bytes; 0 at a clean EOF before the first byte, -1 otherwise. */
static int read_all(int fd, char *buf, size_t n)
{
	size_t got = 0;
	while (got < n) {
		ssize_t r = read(fd, buf + got, n - got);
		if (r < 0 && errno == EINTR)
			continue;
		if (r <= 0)
			return got == 0 && r == 0 ? 0 : -1;
		got += (size_t)r;
	}
	return 1;
}

static int write_all(int fd, const char *buf, size_t n)
{
	while (n > 0) {
		ssize_t w = write(fd, buf, n);
		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0)
			return -1;
		buf += w;
		n -= (size_t)w;
	}
	return 0;
}

static void receive(int fd)
{
	unsigned long long total = 0;
	for (;;) {
		ssize_t r = read(fd, block, BLOCK);
		if (r < 0 && errno == EINTR)
			continue;
		if (r < 0) {
			fail("receive");
			return;
		}
		if (r == 0)
			break;
		total += (unsigned long long)r;
	}
	char line[32];
	int n = snprintf(line, sizeof line, "%llu\n", total);
	if (write_all(fd, line, (size_t)n) < 0)
		fail("receive: the count");
}

static void send_blocks(int fd)
{
	unsigned char count[4];
	if (read_all(fd, (char *)count, 4) != 1) {
		fail("send: the block count");
		return;
	}
	unsigned long blocks = count[0] | count[1] << 8 | count[2] << 16 | (unsigned long)count[3] << 24;
	for (unsigned long i = 0; i < blocks; i++) {
		if (write_all(fd, block, BLOCK) < 0) {
			fail("send");
			return;
		}
	}
}

static void echo(int fd)
{
	int one = 1;
	if (setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one) < 0)
		fail("echo: TCP_NODELAY");
	char message[MESSAGE];
	for (;;) {
		int r = read_all(fd, message, MESSAGE);
		if (r == 0)
			return;
		if (r < 0 || write_all(fd, message, MESSAGE) < 0) {
			fail("echo");
			return;
		}
	}
}

static void udp_echo(int fd)
{
	char message[2048];
	for (;;) {
		struct sockaddr_in peer;
		socklen_t len = sizeof peer;
		ssize_t r = recvfrom(fd, message, sizeof message, 0, (struct sockaddr *)&peer, &len);
		if (r < 0 && errno == EINTR)
			continue;
		if (r < 0) {
			fail("udp: recvfrom");
			_exit(1);
		}
		if (sendto(fd, message, (size_t)r, 0, (struct sockaddr *)&peer, len) < 0)
			fail("udp: sendto");
	}
}

int main(int argc, char **argv)
{
	int port = argc > 1 ? atoi(argv[1]) : 5001;
	struct sockaddr_in addr;
	memset(&addr, 0, sizeof addr);
	addr.sin_family = AF_INET;
	addr.sin_port = htons((unsigned short)port);
	addr.sin_addr.s_addr = htonl(INADDR_ANY);
	memset(block, 'x', sizeof block);
	signal(SIGPIPE, SIG_IGN);

	int udp = socket(AF_INET, SOCK_DGRAM, 0);
	if (udp < 0 || bind(udp, (struct sockaddr *)&addr, sizeof addr) < 0) {
		fail("udp socket");
		return 1;
	}
	int one = 1;
	int tcp = socket(AF_INET, SOCK_STREAM, 0);
	if (tcp < 0 || setsockopt(tcp, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) < 0 ||
	    bind(tcp, (struct sockaddr *)&addr, sizeof addr) < 0 || listen(tcp, 8) < 0) {
		fail("tcp socket");
		return 1;
	}
	pid_t udp_child = fork();
	if (udp_child < 0) {
		fail("fork");
		return 1;
	}
	if (udp_child == 0) {
		close(tcp);
		udp_echo(udp);
	}
	close(udp);
	printf("netserve: listening on %d\n", port);
	fflush(stdout);
	for (;;) {
		int fd = accept(tcp, NULL, NULL);
		if (fd < 0) {
			if (errno != EINTR)
				fail("accept");
			continue;
		}
		char command;
		if (read_all(fd, &command, 1) != 1) {
			close(fd);
			continue;
		}
		switch (command) {
		case 'P':
			write_all(fd, "p", 1);
			break;
		case 'R':
			receive(fd);
			break;
		case 'S':
			send_blocks(fd);
			break;
		case 'E':
			echo(fd);
			break;
		case 'Q':
			write_all(fd, "q", 1);
			close(fd);
			kill(udp_child, SIGKILL);
			waitpid(udp_child, NULL, 0);
			printf("netserve: done\n");
			fflush(stdout);
			return 0;
		default:
			printf("netserve: error: unknown command byte %d\n", command);
			fflush(stdout);
		}
		close(fd);
	}
}
