/* linux-tests: checks of Linux system calls' results and error codes, run the same way on
 * the host Linux and in the Warden guest, whose outputs must be the same.
 *
 *     linux-tests AREA...     run the areas in order (process memory files writes pipes
 *                             signals time misc sockets threads events); no argument: all of them
 *
 * Each area prints `ok <check>` or `FAIL <check>: expected X got Y` lines and then
 * `area <name>: all checks passed` or `area <name>: <n> checks failed`; the program exits
 * 0 when all its areas passed, 1 otherwise, 2 on a bad argument. It must be started with
 * an absolute path (some checks execute it again: `--exit`, `--args`, `--fd-closed`,
 * `--dispositions`). tests/linux/expected/<area>.out holds each area's expected output. */
#include "check.h"

#include <stdlib.h>
#include <sys/wait.h>

static const struct {
	const char *name;
	void (*run)(void);
} areas[] = {
	{ "process", area_process }, { "memory", area_memory }, { "files", area_files },
	{ "writes", area_writes },   { "pipes", area_pipes },   { "signals", area_signals },
	{ "time", area_time },	     { "misc", area_misc },	    { "sockets", area_sockets },
	{ "threads", area_threads }, { "events", area_events },
};
#define AREAS (sizeof areas / sizeof areas[0])

static int run_area(const char *name)
{
	for (size_t i = 0; i < AREAS; i++) {
		if (strcmp(areas[i].name, name) != 0)
			continue;
		failures = 0;
		areas[i].run();
		if (failures == 0)
			say("area %s: all checks passed", name);
		else
			say("area %s: %d checks failed", name, failures);
		return failures == 0;
	}
	say("unknown area %s", name);
	exit(2);
}

int main(int argc, char **argv)
{
	self_path = argv[0];
	if (argc > 1 && strncmp(argv[1], "--", 2) == 0)
		return exec_mode(argc, argv);
	int passed = 1;
	if (argc == 1) {
		for (size_t i = 0; i < AREAS; i++)
			passed &= run_area(areas[i].name);
	} else {
		for (int i = 1; i < argc; i++)
			passed &= run_area(argv[i]);
	}
	return passed ? 0 : 1;
}
