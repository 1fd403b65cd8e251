/* Area `threads`: glibc pthreads on clone(CLONE_THREAD): thread ids and the thread group,
 * 4 threads with a mutex, a condition variable and a barrier, a futex stress (8 threads x
 * 100,000 lock/unlock of one mutex), thread exit and join (a thread's return value,
 * pthread_exit, a detached thread), futex calls themselves (EAGAIN, ETIMEDOUT, wake
 * counts, requeue), signals to threads (pthread_kill runs the handler in the thread it
 * names; a process-directed signal goes to the thread that does not block it; per-thread
 * masks), sigaltstack per thread, sched_yield, sched_getaffinity, and exit_group from a
 * thread ending the whole process. */
#include "check.h"

#include <linux/futex.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <time.h>

static long futex(uint32_t *word, int op, uint32_t value, const struct timespec *timeout,
		  uint32_t *word2, uint32_t value3)
{
	return syscall(SYS_futex, word, op, value, timeout, word2, value3);
}

static pid_t gettid_(void)
{
	return (pid_t)syscall(SYS_gettid);
}

/* Thread ids: each thread has its own, getpid is the process's. */
static pid_t seen_pid, seen_tid;

static void *identity(void *arg)
{
	(void)arg;
	seen_pid = getpid();
	seen_tid = gettid_();
	return (void *)42;
}

static void check_identity(void)
{
	pthread_t t;
	void *ret = NULL;
	check_eq("main thread's tid is the pid", getpid(), gettid_());
	check_eq("pthread_create", 0, pthread_create(&t, NULL, identity, NULL));
	check_eq("pthread_join", 0, pthread_join(t, &ret));
	check_eq("join returns the thread's value", 42, (long)ret);
	check_eq("a thread's getpid is the process's", getpid(), seen_pid);
	check("a thread has a tid of its own", seen_tid != getpid() && seen_tid > 0,
	      "tid %d, pid %d", (int)seen_tid, (int)getpid());
}

/* 4 threads: a mutex-protected counter, a condition variable, a barrier. */
#define WORKERS 4
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t cond = PTHREAD_COND_INITIALIZER;
static pthread_barrier_t barrier;
static int ready, go, counter, serial;

static void *worker(void *arg)
{
	(void)arg;
	pthread_mutex_lock(&lock);
	ready++;
	pthread_cond_broadcast(&cond);
	while (!go)
		pthread_cond_wait(&cond, &lock);
	pthread_mutex_unlock(&lock);
	for (int i = 0; i < 1000; i++) {
		pthread_mutex_lock(&lock);
		counter++;
		pthread_mutex_unlock(&lock);
	}
	if (pthread_barrier_wait(&barrier) == PTHREAD_BARRIER_SERIAL_THREAD)
		__atomic_add_fetch(&serial, 1, __ATOMIC_SEQ_CST);
	return NULL;
}

static void check_workers(void)
{
	pthread_t t[WORKERS];
	int created = 0;
	pthread_barrier_init(&barrier, NULL, WORKERS + 1);
	for (int i = 0; i < WORKERS; i++)
		created += pthread_create(&t[i], NULL, worker, NULL) == 0;
	check_eq("4 threads created", WORKERS, created);
	pthread_mutex_lock(&lock);
	while (ready < WORKERS)
		pthread_cond_wait(&cond, &lock);
	go = 1;
	pthread_cond_broadcast(&cond);
	pthread_mutex_unlock(&lock);
	if (pthread_barrier_wait(&barrier) == PTHREAD_BARRIER_SERIAL_THREAD)
		__atomic_add_fetch(&serial, 1, __ATOMIC_SEQ_CST);
	int joined = 0;
	for (int i = 0; i < WORKERS; i++)
		joined += pthread_join(t[i], NULL) == 0;
	check_eq("4 threads joined", WORKERS, joined);
	check_eq("condition variable: all were ready", WORKERS, ready);
	check_eq("mutex: no increment lost", WORKERS * 1000, counter);
	check_eq("barrier: one serial thread", 1, serial);
	pthread_barrier_destroy(&barrier);
}

/* The futex stress: 8 threads x 100,000 lock/unlock. */
#define STRESS_THREADS 8
#define STRESS_ROUNDS 100000
static pthread_mutex_t stress_lock = PTHREAD_MUTEX_INITIALIZER;
static long stress_total;

static void *stress(void *arg)
{
	(void)arg;
	for (int i = 0; i < STRESS_ROUNDS; i++) {
		pthread_mutex_lock(&stress_lock);
		stress_total++;
		pthread_mutex_unlock(&stress_lock);
	}
	return NULL;
}

static void check_stress(void)
{
	pthread_t t[STRESS_THREADS];
	int created = 0, joined = 0;
	for (int i = 0; i < STRESS_THREADS; i++)
		created += pthread_create(&t[i], NULL, stress, NULL) == 0;
	for (int i = 0; i < created; i++)
		joined += pthread_join(t[i], NULL) == 0;
	check_eq("stress: 8 threads created and joined", 2 * STRESS_THREADS, created + joined);
	check_eq("stress: 800000 lock/unlock, none lost", (long)STRESS_THREADS * STRESS_ROUNDS,
		 stress_total);
}

/* Thread exit: pthread_exit's value, a detached thread's end. */
static volatile int detached_ran;

static void *exits(void *arg)
{
	(void)arg;
	pthread_exit((void *)7);
	return NULL;
}

static void *detached(void *arg)
{
	(void)arg;
	__atomic_store_n(&detached_ran, 1, __ATOMIC_SEQ_CST);
	return NULL;
}

static void check_exit(void)
{
	pthread_t t;
	void *ret = NULL;
	pthread_create(&t, NULL, exits, NULL);
	check_eq("pthread_exit: joined", 0, pthread_join(t, &ret));
	check_eq("pthread_exit: its value", 7, (long)ret);
	pthread_attr_t attr;
	pthread_attr_init(&attr);
	pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
	check_eq("detached thread created", 0, pthread_create(&t, &attr, detached, NULL));
	pthread_attr_destroy(&attr);
	for (int i = 0; i < 1000 && !__atomic_load_n(&detached_ran, __ATOMIC_SEQ_CST); i++)
		usleep(1000);
	check_eq("detached thread ran", 1, detached_ran);
}

/* futex itself. */
static uint32_t fword, fword2;
static volatile int waiting;

static void *futex_waiter(void *arg)
{
	uint32_t *word = arg;
	__atomic_add_fetch(&waiting, 1, __ATOMIC_SEQ_CST);
	while (__atomic_load_n(word, __ATOMIC_SEQ_CST) == 0)
		futex(word, FUTEX_WAIT_PRIVATE, 0, NULL, NULL, 0);
	return NULL;
}

/* Waits until `n` threads wait on a futex (they announced it; a short sleep lets them
 * enter the call). */
static void until_waiting(int n)
{
	while (__atomic_load_n(&waiting, __ATOMIC_SEQ_CST) < n)
		sched_yield();
	usleep(50000);
}

static void check_futex(void)
{
	struct timespec short_wait = { 0, 10 * 1000 * 1000 };
	fword = 1;
	errno = 0;
	check_errno("futex wait: value differs", futex(&fword, FUTEX_WAIT, 0, NULL, NULL, 0),
		    EAGAIN);
	fword = 0;
	check_errno("futex wait: timeout", futex(&fword, FUTEX_WAIT, 0, &short_wait, NULL, 0),
		    ETIMEDOUT);
	check_eq("futex wake: nobody waits", 0, futex(&fword, FUTEX_WAKE, 1, NULL, NULL, 0));
	check_errno("futex: unaligned word",
		    futex((uint32_t *)((char *)&fword + 1), FUTEX_WAKE, 1, NULL, NULL, 0), EINVAL);
	check_errno("futex: bitset 0", futex(&fword, FUTEX_WAIT_BITSET, 0, NULL, NULL, 0),
		    EINVAL);

	pthread_t t[2];
	waiting = 0;
	pthread_create(&t[0], NULL, futex_waiter, &fword);
	pthread_create(&t[1], NULL, futex_waiter, &fword);
	until_waiting(2);
	/* Requeue both from fword to fword2, waking none. */
	check_eq("futex cmp_requeue: moved 2",
		 2, futex(&fword, FUTEX_CMP_REQUEUE_PRIVATE, 0, (void *)(uintptr_t)2, &fword2, 0));
	check_errno("futex cmp_requeue: value differs",
		    futex(&fword, FUTEX_CMP_REQUEUE_PRIVATE, 0, (void *)(uintptr_t)2, &fword2, 5),
		    EAGAIN);
	check_eq("futex wake: the old word has none", 0,
		 futex(&fword, FUTEX_WAKE_PRIVATE, 2, NULL, NULL, 0));
	__atomic_store_n(&fword, 1, __ATOMIC_SEQ_CST);
	check_eq("futex wake: the requeued ones, one at a time", 1,
		 futex(&fword2, FUTEX_WAKE_PRIVATE, 1, NULL, NULL, 0));
	usleep(20000);
	check_eq("futex wake: the other", 1, futex(&fword2, FUTEX_WAKE_PRIVATE, 1, NULL, NULL, 0));
	check_eq("futex waiters joined", 0, pthread_join(t[0], NULL) | pthread_join(t[1], NULL));
}

/* Signals. */
static volatile pid_t handled_in;
static volatile int handled;

static void on_usr1(int signo)
{
	(void)signo;
	handled_in = gettid_();
	__atomic_add_fetch(&handled, 1, __ATOMIC_SEQ_CST);
}

static volatile pid_t target_tid;
static volatile int stop_target;

static void *signal_target(void *arg)
{
	int unblock = arg != NULL;
	if (unblock) {
		sigset_t set;
		sigemptyset(&set);
		sigaddset(&set, SIGUSR1);
		pthread_sigmask(SIG_UNBLOCK, &set, NULL);
	}
	target_tid = gettid_();
	while (!__atomic_load_n(&stop_target, __ATOMIC_SEQ_CST))
		usleep(1000);
	return NULL;
}

static void wait_handled(int n)
{
	for (int i = 0; i < 2000 && __atomic_load_n(&handled, __ATOMIC_SEQ_CST) < n; i++)
		usleep(1000);
}

static void check_signals(void)
{
	struct sigaction sa;
	memset(&sa, 0, sizeof sa);
	sa.sa_handler = on_usr1;
	sigaction(SIGUSR1, &sa, NULL);
	pthread_t t;

	/* pthread_kill: the handler runs in the thread named. */
	stop_target = 0;
	target_tid = 0;
	handled = 0;
	pthread_create(&t, NULL, signal_target, NULL);
	while (!target_tid)
		sched_yield();
	check_eq("pthread_kill", 0, pthread_kill(t, SIGUSR1));
	wait_handled(1);
	check_eq("pthread_kill: handled once", 1, handled);
	check("pthread_kill: in the thread named", handled_in == target_tid, "in %s",
	      handled_in == getpid() ? "the main thread" : "another thread");
	stop_target = 1;
	pthread_join(t, NULL);
	errno = 0;
	check_errno("tgkill: no such thread",
		    syscall(SYS_tgkill, getpid(), getpid() + 100000, SIGUSR1), ESRCH);
	check_errno("tgkill: another process's group",
		    syscall(SYS_tgkill, getpid() + 100000, getpid(), SIGUSR1), ESRCH);

	/* A process-directed signal: the main thread blocks it, the other thread not. */
	sigset_t set, old;
	sigemptyset(&set);
	sigaddset(&set, SIGUSR1);
	pthread_sigmask(SIG_BLOCK, &set, &old);
	stop_target = 0;
	target_tid = 0;
	handled = 0;
	pthread_create(&t, NULL, signal_target, (void *)1);
	while (!target_tid)
		sched_yield();
	check_eq("kill to the process", 0, kill(getpid(), SIGUSR1));
	wait_handled(1);
	check_eq("kill: handled once", 1, handled);
	check("kill: by the thread that does not block it", handled_in == target_tid, "in %s",
	      handled_in == getpid() ? "the main thread" : "another thread");
	sigset_t pending;
	sigpending(&pending);
	check_eq("kill: nothing left pending for the main thread", 0,
		 sigismember(&pending, SIGUSR1));
	stop_target = 1;
	pthread_join(t, NULL);
	pthread_sigmask(SIG_SETMASK, &old, NULL);
	sa.sa_handler = SIG_DFL;
	sigaction(SIGUSR1, &sa, NULL);
}

/* sigaltstack is per thread. */
static void *altstack_thread(void *arg)
{
	(void)arg;
	stack_t ss;
	sigaltstack(NULL, &ss);
	return (void *)(long)((ss.ss_flags & SS_DISABLE) != 0);
}

static void check_altstack(void)
{
	static char stack[65536];
	stack_t ss = { .ss_sp = stack, .ss_size = sizeof stack, .ss_flags = 0 }, old;
	check_ok("sigaltstack", sigaltstack(&ss, &old));
	pthread_t t;
	void *disabled = NULL;
	pthread_create(&t, NULL, altstack_thread, NULL);
	pthread_join(t, &disabled);
	check_eq("sigaltstack: a new thread has none", 1, (long)disabled);
	sigaltstack(&old, NULL);
}

/* Scheduling calls. */
static void check_sched(void)
{
	cpu_set_t cpus;
	CPU_ZERO(&cpus);
	check_ok("sched_getaffinity", sched_getaffinity(0, sizeof cpus, &cpus));
	check("sched_getaffinity: at least one CPU", CPU_COUNT(&cpus) >= 1, "%d", CPU_COUNT(&cpus));
	check_eq("sched_yield", 0, sched_yield());
}

/* exit_group from a thread ends the process. */
static void *group_exit(void *arg)
{
	(void)arg;
	exit(5);
}

static void check_exit_group(void)
{
	pid_t child = fork();
	if (child == 0) {
		pthread_t t;
		pthread_create(&t, NULL, group_exit, NULL);
		for (;;)
			pause();
	}
	check_status("exit from a thread ends the process", wait_for(child), 5, 0);
	child = fork();
	if (child == 0) {
		pthread_t t;
		stop_target = 0;
		target_tid = 0;
		pthread_create(&t, NULL, signal_target, NULL);
		while (!target_tid)
			sched_yield();
		/* SIGTERM's default action, sent to one thread, ends every thread. */
		pthread_kill(t, SIGTERM);
		for (;;)
			pause();
	}
	check_status("a fatal signal to a thread ends the process", wait_for(child), -1, SIGTERM);
}

void area_threads(void)
{
	check_identity();
	check_workers();
	check_stress();
	check_exit();
	check_futex();
	check_signals();
	check_altstack();
	check_sched();
	check_exit_group();
}
