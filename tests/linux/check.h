/* The checks' common part: how a check reports, so that every area prints the same kind
 * of deterministic lines on the host and in the guest:
 *
 *     ok <name>
 *     FAIL <name>: expected <what> got <what>
 *
 * and never a pid, an address or a time. Lines are written with write(2), unbuffered, so
 * a fork never duplicates pending output and a crash loses nothing already checked. */
#ifndef LINUX_TESTS_CHECK_H
#define LINUX_TESTS_CHECK_H

/* The GNU C library's names of Linux calls (pipe2, dup3, getdents64's struct dirent64). */
#define _GNU_SOURCE

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

/* Checks that failed in this process (each area resets it). */
extern int failures;
/* argv[0] of the program: an absolute path, so that a test can execute itself. */
extern const char *self_path;

/* Writes one formatted line to stdout. */
void say(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* `ok name` when cond holds, else `FAIL name: <detail>` (the detail formatted). */
void check(const char *name, int cond, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* Expects the integer `got` to equal `expected` (a -1 is shown with errno's name). */
void check_eq(const char *name, long expected, long got);
/* Expects a call to have failed with -1 and errno `expected` (errno as the call left it). */
void check_errno(const char *name, long ret, int expected);
/* Expects a call to have succeeded (not -1); reports errno otherwise. */
void check_ok(const char *name, long ret);
/* Expects wait status `status` to be exit with `code`, or killed by `signal` when code < 0. */
void check_status(const char *name, int status, int code, int signal);
/* The name of an errno value (`ENOENT`), or its number. */
const char *errno_name(int e);
/* Waits for child `pid` and returns its status word (-1 with errno if wait4 failed). */
int wait_for(int pid);

/* The areas (one file each). */
void area_process(void);
void area_memory(void);
void area_files(void);
void area_writes(void);
void area_pipes(void);
void area_signals(void);
void area_time(void);
void area_misc(void);
void area_sockets(void);
void area_threads(void);
void area_events(void);

/* Entry points of the program when it executes itself (`linux-tests --<mode> ...`). */
int exec_mode(int argc, char **argv);

#endif
