/* Area `signals`: sigaction (the handler runs, SA_SIGINFO's si_signo/si_code, the old action
 * answered, SIG_IGN), sigprocmask and sigpending, kill (to itself, to a child, errors),
 * SIGCHLD, the default actions' wait statuses, EINTR of a blocking read and of nanosleep,
 * SA_RESTART, and what execve keeps. */
#include "check.h"

#include <fcntl.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <time.h>

static volatile sig_atomic_t caught, caught_signo, caught_code, chld;

static void on_signal(int signo)
{
	caught++;
	caught_signo = signo;
}

static void on_info(int signo, siginfo_t *info, void *context)
{
	(void)context;
	caught++;
	caught_signo = signo;
	caught_code = info->si_code;
}

static void on_chld(int signo)
{
	(void)signo;
	chld++;
}

static void handle(int signo, void (*handler)(int), int flags)
{
	struct sigaction sa;
	memset(&sa, 0, sizeof sa);
	sa.sa_handler = handler;
	sa.sa_flags = flags;
	sigemptyset(&sa.sa_mask);
	sigaction(signo, &sa, NULL);
}

/* A child that sends `signo` to its parent every 20 ms until `stop` has a byte (or 5 s),
 * then writes one byte into `data` when that is not -1. */
static int pester(int signo, int stop, int data, int times)
{
	int pid = fork();
	if (pid == 0) {
		struct timespec pause = { 0, 20 * 1000 * 1000 };
		int parent = getppid();
		char c;
		for (int i = 0; i < times; i++) {
			kill(parent, signo);
			nanosleep(&pause, NULL);
			if (read(stop, &c, 1) == 1)
				break;
		}
		if (data >= 0)
			write(data, "d", 1);
		_exit(0);
	}
	return pid;
}

void area_signals(void)
{
	struct sigaction sa, old;
	sigset_t set, pending;

	/* A handler runs for a signal sent to ourselves, before kill returns. */
	handle(SIGUSR1, on_signal, 0);
	caught = 0;
	check_eq("kill to itself", 0, kill(getpid(), SIGUSR1));
	check_eq("handler ran once", 1, caught);
	check_eq("handler got the signal number", SIGUSR1, caught_signo);
	check_eq("raise", 0, raise(SIGUSR1));
	check_eq("handler ran for raise", 2, caught);

	memset(&sa, 0, sizeof sa);
	sa.sa_sigaction = on_info;
	sa.sa_flags = SA_SIGINFO;
	sigaction(SIGUSR2, &sa, NULL);
	caught = caught_code = 0;
	kill(getpid(), SIGUSR2);
	check("SA_SIGINFO handler gets si_signo and si_code SI_USER",
	      caught == 1 && caught_signo == SIGUSR2 && caught_code == SI_USER,
	      "expected 1 call with %d/%d got %d calls with %d/%d", SIGUSR2, SI_USER, (int)caught,
	      (int)caught_signo, (int)caught_code);
	check_eq("sigaction answers the old action", 0, sigaction(SIGUSR2, NULL, &old));
	check("old action is the handler with SA_SIGINFO",
	      old.sa_sigaction == on_info && (old.sa_flags & SA_SIGINFO),
	      "expected the handler installed");
	check_errno("sigaction of SIGKILL EINVAL", sigaction(SIGKILL, &sa, NULL), EINVAL);
	check_errno("sigaction of signal 0 EINVAL", sigaction(0, &sa, NULL), EINVAL);
	check_errno("sigaction of signal 65 EINVAL", syscall(SYS_rt_sigaction, 65, NULL, &old, 8),
		    EINVAL);

	/* Blocked signals wait in the pending set and come when unblocked. */
	caught = 0;
	sigemptyset(&set);
	sigaddset(&set, SIGUSR1);
	check_eq("sigprocmask SIG_BLOCK", 0, sigprocmask(SIG_BLOCK, &set, NULL));
	kill(getpid(), SIGUSR1);
	check_eq("a blocked signal is not delivered", 0, caught);
	sigpending(&pending);
	check_eq("sigpending has it", 1, sigismember(&pending, SIGUSR1));
	sigset_t now;
	sigprocmask(SIG_BLOCK, NULL, &now);
	check_eq("sigprocmask answers the mask", 1, sigismember(&now, SIGUSR1));
	check_eq("sigprocmask SIG_UNBLOCK", 0, sigprocmask(SIG_UNBLOCK, &set, NULL));
	check_eq("unblocking delivers it", 1, caught);
	sigpending(&pending);
	check_eq("sigpending is empty again", 0, sigismember(&pending, SIGUSR1));
	check_errno("sigprocmask with a bad how EINVAL", sigprocmask(99, &set, NULL), EINVAL);
	sigemptyset(&set);
	sigaddset(&set, SIGKILL);
	sigprocmask(SIG_BLOCK, &set, NULL);
	sigprocmask(SIG_BLOCK, NULL, &now);
	check_eq("SIGKILL cannot be blocked", 0, sigismember(&now, SIGKILL));

	/* Ignored signals vanish. */
	signal(SIGUSR2, SIG_IGN);
	check_eq("kill with an ignored signal", 0, kill(getpid(), SIGUSR2));
	check_eq("kill with signal 0 checks the process", 0, kill(getpid(), 0));
	check_errno("kill of a missing process ESRCH", kill(0x3ffffff0, 0), ESRCH);
	check_errno("kill with a bad signal EINVAL", kill(getpid(), 65), EINVAL);

	/* A child killed by SIGKILL has status word 9. */
	int pid = fork();
	if (pid == 0) {
		kill(getpid(), SIGKILL);
		_exit(1);
	}
	check_eq("status word of a child killed by SIGKILL", SIGKILL, wait_for(pid));

	/* Default actions, seen in the wait status. The child waits in a read the parent ends
	 * (end of file) after the signal, so that it ends even where kill failed. */
	int gate[2];
	pipe(gate);
	pid = fork();
	if (pid == 0) {
		char c;
		close(gate[1]);
		read(gate[0], &c, 1);
		_exit(0);
	}
	close(gate[0]);
	check_eq("kill a child with SIGTERM", 0, kill(pid, SIGTERM));
	close(gate[1]);
	check_status("child killed by SIGTERM", wait_for(pid), -1, SIGTERM);
	pid = fork();
	if (pid == 0) {
		signal(SIGUSR1, SIG_DFL);
		kill(getpid(), SIGUSR1);
		_exit(0);
	}
	check_status("SIGUSR1's default action terminates", wait_for(pid), -1, SIGUSR1);
	pid = fork();
	if (pid == 0) {
		kill(getpid(), SIGCHLD);
		_exit(6);
	}
	check_status("SIGCHLD's default action is to ignore", wait_for(pid), 6, 0);
	pid = fork();
	if (pid == 0) {
		/* The handler is inherited by fork. */
		caught = 0;
		kill(getpid(), SIGUSR1);
		_exit(caught == 1 ? 0 : 1);
	}
	check_status("a forked child keeps the handler", wait_for(pid), 0, 0);

	/* SIGCHLD when a child ends. */
	handle(SIGCHLD, on_chld, 0);
	sigemptyset(&set);
	sigaddset(&set, SIGCHLD);
	sigprocmask(SIG_BLOCK, &set, NULL);
	chld = 0;
	pid = fork();
	if (pid == 0)
		_exit(0);
	sigemptyset(&set);
	int tries = 0;
	while (!chld && tries++ < 100)
		sigsuspend(&set);
	check_eq("SIGCHLD handler ran when the child ended", 1, chld);
	check_status("and the child is waited for", wait_for(pid), 0, 0);
	signal(SIGCHLD, SIG_DFL);
	sigprocmask(SIG_SETMASK, &set, NULL);

	/* A blocking read interrupted by a handled signal: EINTR. Only the signalling child
	 * holds the write end of `data`, so the read ends (end of file) when the child does,
	 * also where no signal came. */
	int data[2], stop[2];
	pipe(data);
	pipe2(stop, O_NONBLOCK);
	handle(SIGUSR1, on_signal, 0);
	caught = 0;
	pid = pester(SIGUSR1, stop[0], -1, 250);
	close(data[1]);
	char c;
	long r = read(data[0], &c, 1);
	check_errno("a blocking read interrupted by a signal EINTR", r, EINTR);
	write(stop[1], "s", 1);
	check_status("signalling child exits", wait_for(pid), 0, 0);
	check("the handler ran", caught >= 1, "expected >= 1 got %d", (int)caught);

	/* With SA_RESTART the read goes on and returns the data. */
	handle(SIGUSR1, on_signal, SA_RESTART);
	while (read(stop[0], &c, 1) == 1)
		;
	caught = 0;
	close(data[0]);
	pipe(data);
	pid = pester(SIGUSR1, stop[0], data[1], 3);
	close(data[1]);
	r = read(data[0], &c, 1);
	check("SA_RESTART read returns the data after signals", r == 1 && c == 'd' && caught >= 1,
	      "expected 1 byte after >= 1 signal got %ld after %d", r, (int)caught);
	check_status("restart child exits", wait_for(pid), 0, 0);

	/* nanosleep interrupted: EINTR, with the remaining time. */
	handle(SIGUSR1, on_signal, 0);
	while (read(stop[0], &c, 1) == 1)
		;
	pid = pester(SIGUSR1, stop[0], -1, 250);
	struct timespec ten = { 10, 0 }, left = { 0, 0 };
	r = nanosleep(&ten, &left);
	check_errno("nanosleep interrupted by a signal EINTR", r, EINTR);
	check("nanosleep answers the remaining time",
	      left.tv_sec > 0 && left.tv_sec <= 10, "expected 0 < remaining <= 10 s");
	write(stop[1], "s", 1);
	wait_for(pid);
	close(data[0]);
	close(stop[0]);
	close(stop[1]);

	/* execve: a handled signal goes back to its default, an ignored one stays ignored, the
	 * mask is kept. */
	signal(SIGUSR2, SIG_IGN);
	sigemptyset(&set);
	sigaddset(&set, SIGHUP);
	sigprocmask(SIG_BLOCK, &set, NULL);
	pid = fork();
	if (pid == 0) {
		char *args[] = { (char *)self_path, "--dispositions", NULL };
		char *env[] = { NULL };
		execve(self_path, args, env);
		_exit(99);
	}
	check_status("execve resets handlers and keeps SIG_IGN and the mask", wait_for(pid), 0, 0);
	sigprocmask(SIG_UNBLOCK, &set, NULL);
	signal(SIGUSR1, SIG_DFL);
	signal(SIGUSR2, SIG_DFL);
}
