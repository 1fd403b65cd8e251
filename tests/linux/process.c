/* Area `process`: getpid/getppid, fork (the child's memory a copy) and vfork, wait4's status
 * words and errors, execve (arguments, environment, errors, close-on-exec), exit codes and
 * orphans. Also the modes the program runs in when it executes itself. */
#include "check.h"

#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <sys/wait.h>

int exec_mode(int argc, char **argv)
{
	const char *mode = argv[1];
	if (strcmp(mode, "--exit") == 0 && argc == 3)
		return atoi(argv[2]);
	if (strcmp(mode, "--args") == 0) {
		const char *v = getenv("LT_VAR");
		return !(argc == 4 && strcmp(argv[2], "hello world") == 0 && argv[3][0] == 0 && v &&
			 strcmp(v, "value") == 0 && getenv("PATH") == NULL);
	}
	if (strcmp(mode, "--fd-closed") == 0 && argc == 3)
		return !(fcntl(atoi(argv[2]), F_GETFD) == -1 && errno == EBADF);
	if (strcmp(mode, "--fd-open") == 0 && argc == 3)
		return fcntl(atoi(argv[2]), F_GETFD) == -1;
	if (strcmp(mode, "--dispositions") == 0) {
		/* After execve a handled signal is back to SIG_DFL, an ignored one stays ignored,
		 * the blocked mask is kept. */
		struct sigaction usr1, usr2;
		sigset_t mask;
		sigaction(SIGUSR1, NULL, &usr1);
		sigaction(SIGUSR2, NULL, &usr2);
		sigprocmask(SIG_BLOCK, NULL, &mask);
		int code = 0;
		if (usr1.sa_handler != SIG_DFL)
			code |= 1;
		if (usr2.sa_handler != SIG_IGN)
			code |= 2;
		if (!sigismember(&mask, SIGHUP))
			code |= 4;
		return code;
	}
	say("unknown mode %s", mode);
	return 2;
}

/* A child that runs `body` and exits with its result. */
static int spawn(int (*body)(void))
{
	int pid = fork();
	if (pid == 0)
		_exit(body());
	return pid;
}

static int parent_pid;
static int child_sees_parent(void)
{
	return getppid() == parent_pid ? 0 : 1;
}

static volatile int copied = 1;
static int child_writes_copy(void)
{
	copied = 2;
	return copied == 2 ? 0 : 1;
}

static int run_self(char *const args[], char *const env[])
{
	int pid = fork();
	if (pid == 0) {
		execve(self_path, args, env);
		_exit(99);
	}
	return wait_for(pid);
}

void area_process(void)
{
	int status;
	check("getpid positive", getpid() > 0, "expected > 0 got %d", getpid());
	check("gettid equals getpid", syscall(SYS_gettid) == getpid(), "expected the pid");
	check("getppid differs from getpid", getppid() != getpid(), "expected another pid");
	errno = 0;
	check_errno("wait4 without children ECHILD", wait4(-1, &status, 0, NULL), ECHILD);
	check_errno("wait4 WNOHANG without children ECHILD", wait4(-1, &status, WNOHANG, NULL),
		    ECHILD);

	parent_pid = getpid();
	int pid = spawn(child_sees_parent);
	check("fork returns the child's pid", pid > 0 && pid != parent_pid, "expected a new pid");
	check_status("fork child's getppid is the parent", wait_for(pid), 0, 0);

	pid = spawn(child_writes_copy);
	check_status("fork child writes its copy", wait_for(pid), 0, 0);
	check_eq("fork child's write not seen by the parent", 1, copied);

	/* Exit codes and the raw status word (code << 8). */
	pid = fork();
	if (pid == 0)
		_exit(42);
	int r = wait4(pid, &status, 0, NULL);
	check_eq("wait4 returns the child's pid", 1, r == pid);
	check_eq("status word of exit 42", 42 << 8, status);
	pid = fork();
	if (pid == 0)
		_exit(256 + 7);
	check_status("exit code is taken modulo 256", wait_for(pid), 7, 0);
	pid = fork();
	if (pid == 0)
		exit(3); /* through the C library's exit (exit_group) */
	check_status("exit through the C library", wait_for(pid), 3, 0);

	/* WNOHANG on a running child returns 0; wait4 for another pid is ECHILD. */
	int gate[2];
	if (pipe(gate) == 0) {
		pid = fork();
		if (pid == 0) {
			char c;
			close(gate[1]);
			_exit(read(gate[0], &c, 1) == 0 ? 5 : 6);
		}
		close(gate[0]);
		check_eq("wait4 WNOHANG on a running child returns 0", 0,
			 wait4(pid, &status, WNOHANG, NULL));
		check_errno("wait4 for a pid that is no child ECHILD",
			    wait4(pid + 1000000, &status, 0, NULL), ECHILD);
		close(gate[1]);
		check_status("child sees end of file once the parent closes", wait_for(pid), 5, 0);
	} else {
		check("pipe for WNOHANG", 0, "expected success got %s", errno_name(errno));
	}

	/* Two children, waited for with -1: each pid comes back once. */
	int a = fork();
	if (a == 0)
		_exit(1);
	int b = fork();
	if (b == 0)
		_exit(2);
	int first = wait4(-1, &status, 0, NULL);
	int first_code = WEXITSTATUS(status);
	int second = wait4(-1, &status, 0, NULL);
	int second_code = WEXITSTATUS(status);
	check("wait4 -1 reaps both children",
	      ((first == a && second == b) || (first == b && second == a)) &&
		      first_code + second_code == 3 &&
		      (first == a ? first_code == 1 : first_code == 2),
	      "expected each child once with its code");

	/* vfork: the parent goes on once the child has ended (that the child borrows the
	 * parent's memory meanwhile is area memory's). */
	pid = vfork();
	if (pid == 0)
		_exit(4);
	check_status("vfork child exits", wait_for(pid), 4, 0);

	/* execve. */
	char *exit17[] = { (char *)self_path, "--exit", "17", NULL };
	char *no_env[] = { NULL };
	check_status("execve runs the program (exit 17)", run_self(exit17, no_env), 17, 0);
	char *args[] = { (char *)self_path, "--args", "hello world", "", NULL };
	char *env[] = { "LT_VAR=value", NULL };
	check_status("execve passes argv and envp", run_self(args, env), 0, 0);
	pid = vfork();
	if (pid == 0) {
		execve(self_path, exit17, no_env);
		_exit(99);
	}
	check_status("vfork then execve", wait_for(pid), 17, 0);
	check_errno("execve of a missing file ENOENT", execve("/nonexistent/program", args, env),
		    ENOENT);
	check_errno("execve of a file without x bit EACCES", execve("/etc/passwd", args, env),
		    EACCES);
	check_errno("execve of a directory EACCES", execve("/etc", args, env), EACCES);
	check_errno("execve with a bad path pointer EFAULT",
		    syscall(SYS_execve, (char *)8, args, env), EFAULT);

	/* Close-on-exec: the flagged descriptor is gone in the new image, the other kept. */
	int fd = open("/etc/passwd", O_RDONLY | O_CLOEXEC);
	int kept = open("/etc/passwd", O_RDONLY);
	if (fd >= 0 && kept >= 0) {
		char number[16];
		snprintf(number, sizeof number, "%d", fd);
		char *closed[] = { (char *)self_path, "--fd-closed", number, NULL };
		check_status("O_CLOEXEC descriptor closed by execve", run_self(closed, no_env), 0,
			     0);
		char number2[16];
		snprintf(number2, sizeof number2, "%d", kept);
		char *open_args[] = { (char *)self_path, "--fd-open", number2, NULL };
		check_status("other descriptor kept by execve", run_self(open_args, no_env), 0, 0);
	} else {
		check("open for close-on-exec", 0, "expected success got %s", errno_name(errno));
	}
	close(fd);
	close(kept);

	/* An orphan gets a new parent (init or a subreaper) and is no longer ours to wait. */
	int report[2];
	if (pipe(report) == 0) {
		pid = fork();
		if (pid == 0) {
			int dying = getpid();
			int grandchild = fork();
			if (grandchild == 0) {
				/* Waits until its parent is gone, then reports. */
				int tries = 0;
				while (getppid() == dying && tries++ < 100000)
					sched_yield();
				char c = getppid() != dying ? 'y' : 'n';
				write(report[1], &c, 1);
				_exit(0);
			}
			_exit(grandchild > 0 ? 0 : 1);
		}
		close(report[1]);
		check_status("orphan's parent exits", wait_for(pid), 0, 0);
		char c = 0;
		check_eq("orphan reports", 1, read(report[0], &c, 1));
		check_eq("orphan re-parented", 'y', c);
		close(report[0]);
	}
	/* The orphan may have become our child (we are init in a guest): reap it. */
	while (wait4(-1, &status, WNOHANG, NULL) > 0)
		;
}
