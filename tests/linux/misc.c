/* Area `misc`: uname, getrandom, prlimit64/getrlimit/setrlimit (and EMFILE at the limit),
 * sysinfo, umask, getcwd/chdir/fchdir, arch_prctl's TLS base, sched_yield, ioctl's ENOTTY. */
#include "check.h"

#include <asm/prctl.h>
#include <fcntl.h>
#include <sched.h>
#include <sys/ioctl.h>
#include <sys/random.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/sysinfo.h>
#include <sys/utsname.h>
#include <termios.h>

void area_misc(void)
{
	struct utsname u;
	check_eq("uname", 0, uname(&u));
	check("uname sysname is Linux", strcmp(u.sysname, "Linux") == 0,
	      "expected Linux got %s", u.sysname);
	check("uname machine is x86_64", strcmp(u.machine, "x86_64") == 0,
	      "expected x86_64 got %s", u.machine);
	check("uname release is set", u.release[0] >= '2' && u.release[0] <= '9',
	      "expected a version got %s", u.release);
	check_errno("uname into a bad pointer EFAULT", syscall(SYS_uname, (void *)8), EFAULT);

	unsigned char r1[32], r2[32];
	check_eq("getrandom 32 bytes", 32, getrandom(r1, sizeof r1, 0));
	check_eq("getrandom GRND_NONBLOCK", 32, getrandom(r2, sizeof r2, GRND_NONBLOCK));
	check("two getrandom calls differ", memcmp(r1, r2, sizeof r1) != 0, "expected new bytes");
	check_errno("getrandom with a bad flag EINVAL", getrandom(r1, sizeof r1, 0x100), EINVAL);
	check_errno("getrandom into a bad pointer EFAULT", syscall(SYS_getrandom, (void *)8, 16, 0), EFAULT);

	struct rlimit lim, saved;
	check_eq("prlimit64 RLIMIT_NOFILE", 0, prlimit(0, RLIMIT_NOFILE, NULL, &saved));
	check("soft limit at most the hard one", saved.rlim_cur <= saved.rlim_max,
	      "expected cur <= max");
	check_eq("getrlimit agrees", 0, getrlimit(RLIMIT_NOFILE, &lim));
	check("getrlimit gives the same", lim.rlim_cur == saved.rlim_cur, "expected the same");
	check("RLIMIT_STACK is at least 128 KiB",
	      getrlimit(RLIMIT_STACK, &lim) == 0 &&
		      (lim.rlim_cur == RLIM_INFINITY || lim.rlim_cur >= 128 * 1024),
	      "expected >= 128 KiB");
	lim.rlim_cur = 16;
	lim.rlim_max = saved.rlim_max;
	check_eq("setrlimit RLIMIT_NOFILE to 16", 0, setrlimit(RLIMIT_NOFILE, &lim));
	int fds[20], opened = 0, last = 0;
	for (int i = 0; i < 20; i++) {
		fds[i] = open("/etc/passwd", O_RDONLY);
		if (fds[i] < 0) {
			last = errno;
			break;
		}
		opened++;
	}
	check_eq("open beyond RLIMIT_NOFILE EMFILE", EMFILE, last);
	check("the highest descriptor is below the limit", opened > 0 && fds[opened - 1] == 15,
	      "expected 15 got %d", opened > 0 ? fds[opened - 1] : -1);
	for (int i = 0; i < opened; i++)
		close(fds[i]);
	check_eq("setrlimit back", 0, setrlimit(RLIMIT_NOFILE, &saved));
	lim.rlim_cur = 2;
	lim.rlim_max = 1;
	check_errno("setrlimit with soft above hard EINVAL", setrlimit(RLIMIT_NOFILE, &lim), EINVAL);
	check_errno("getrlimit of a bad resource EINVAL", getrlimit(999, &lim), EINVAL);

	struct sysinfo si;
	check_eq("sysinfo", 0, sysinfo(&si));
	check("sysinfo has memory, a unit and processes",
	      si.totalram > 0 && si.mem_unit >= 1 && si.freeram <= si.totalram && si.procs >= 1,
	      "expected totalram > 0, mem_unit >= 1, freeram <= totalram, procs >= 1");

	mode_t old = umask(027);
	check_eq("umask answers the previous mask", 027, umask(022));
	umask(old);

	char cwd[256], back[256];
	char *here = getcwd(back, sizeof back);
	check("getcwd", here != NULL, "expected success got %s", errno_name(errno));
	check_eq("chdir /etc", 0, chdir("/etc"));
	check("getcwd after chdir", getcwd(cwd, sizeof cwd) && strcmp(cwd, "/etc") == 0,
	      "expected /etc got %s", cwd);
	int fd = open("passwd", O_RDONLY);
	check_ok("open relative to the new directory", fd);
	close(fd);
	check_eq("chdir ..", 0, chdir(".."));
	check("getcwd after chdir ..", getcwd(cwd, sizeof cwd) && strcmp(cwd, "/") == 0,
	      "expected / got %s", cwd);
	check_errno("chdir to a missing directory ENOENT", chdir("/nonexistent"), ENOENT);
	check_errno("chdir to a file ENOTDIR", chdir("/etc/passwd"), ENOTDIR);
	check_errno("getcwd into a too small buffer ERANGE", syscall(SYS_getcwd, cwd, 1), ERANGE);
	int etc = open("/etc", O_RDONLY | O_DIRECTORY);
	check_eq("fchdir", 0, fchdir(etc));
	check("getcwd after fchdir", getcwd(cwd, sizeof cwd) && strcmp(cwd, "/etc") == 0,
	      "expected /etc got %s", cwd);
	close(etc);
	chdir(back);

	unsigned long fs = 0;
	check_eq("arch_prctl ARCH_GET_FS", 0, syscall(SYS_arch_prctl, ARCH_GET_FS, &fs));
	check("the TLS base is set", fs != 0, "expected a base");
	check_eq("sched_yield", 0, sched_yield());
	int p[2];
	pipe(p);
	struct termios tio;
	check_errno("TCGETS on a pipe ENOTTY", ioctl(p[0], TCGETS, &tio), ENOTTY);
	close(p[0]);
	close(p[1]);
}
