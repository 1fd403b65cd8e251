/* Area `files`: reading files and directories that every Linux system (and the guest's
 * initramfs) has — `/`, `/etc`, `/etc/passwd` (whose first line is root's) and this program
 * itself: open/openat, read, lseek, pread, dup/dup2/dup3, fcntl, getdents64, stat, fstat,
 * lstat, access, readlink, close_range, /proc/self/fd and /dev/fd, and the errors ENOENT, EBADF, EISDIR, ENOTDIR, EINVAL, ESPIPE,
 * EFAULT. Writing files is area `writes`. */
#include "check.h"

#include <dirent.h>
#include <linux/close_range.h>
#include <fcntl.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/syscall.h>

/* The names in directory `fd` (via getdents64) contain each of `names`. */
static int lists(int fd, const char *const *names, int count)
{
	char buf[4096];
	int found = 0;
	long n;
	while ((n = syscall(SYS_getdents64, fd, buf, sizeof buf)) > 0) {
		for (long off = 0; off < n;) {
			struct dirent64 *d = (struct dirent64 *)(buf + off);
			for (int i = 0; i < count; i++)
				if (strcmp(d->d_name, names[i]) == 0)
					found |= 1 << i;
			off += d->d_reclen;
		}
	}
	return n == 0 && found == (1 << count) - 1;
}

void area_files(void)
{
	char buf[64];
	int fd = open("/etc/passwd", O_RDONLY);
	check_ok("open /etc/passwd", fd);
	if (fd < 0)
		return;
	check_eq("read 5 bytes", 5, read(fd, buf, 5));
	check("read gives the file's bytes", memcmp(buf, "root:", 5) == 0, "expected root:");
	check_eq("lseek SEEK_CUR answers the offset", 5, lseek(fd, 0, SEEK_CUR));
	check_eq("lseek SEEK_SET", 1, lseek(fd, 1, SEEK_SET));
	check_eq("read after lseek", 3, read(fd, buf, 3));
	check("read after lseek gives bytes at the offset", memcmp(buf, "oot", 3) == 0,
	      "expected oot");
	check_errno("lseek to a negative offset EINVAL", lseek(fd, -1, SEEK_SET), EINVAL);
	check_errno("lseek with a bad whence EINVAL", lseek(fd, 0, 42), EINVAL);
	check_eq("pread at offset 2", 3, pread(fd, buf, 3, 2));
	check("pread gives the bytes at its offset", memcmp(buf, "ot:", 3) == 0, "expected ot:");
	check_eq("pread leaves the offset", 4, lseek(fd, 0, SEEK_CUR));
	check_errno("pread at a negative offset EINVAL", pread(fd, buf, 1, -1), EINVAL);

	struct stat st, fst;
	check_eq("stat /etc/passwd", 0, stat("/etc/passwd", &st));
	check("stat says regular file", S_ISREG(st.st_mode), "expected S_IFREG got 0%o",
	      st.st_mode & S_IFMT);
	check_eq("fstat", 0, fstat(fd, &fst));
	check("fstat agrees with stat", fst.st_size == st.st_size && fst.st_ino == st.st_ino &&
					      fst.st_dev == st.st_dev,
	      "expected the same size, inode and device");
	long end = lseek(fd, 0, SEEK_END);
	check_eq("lseek SEEK_END answers the size", st.st_size, end);
	check_eq("read at end of file gives 0", 0, read(fd, buf, sizeof buf));
	lseek(fd, 0, SEEK_SET);
	long total = 0, n;
	while ((n = read(fd, buf, sizeof buf)) > 0)
		total += n;
	check_eq("reading to the end gives st_size bytes", st.st_size, total);

	/* Duplicates share the offset; dup2 and F_DUPFD pick their number. */
	lseek(fd, 0, SEEK_SET);
	int d = dup(fd);
	check("dup answers a new descriptor", d >= 0 && d != fd, "expected a new descriptor");
	read(fd, buf, 2);
	check_eq("dup shares the offset", 2, lseek(d, 0, SEEK_CUR));
	check_eq("dup2 to 50", 50, dup2(fd, 50));
	check_eq("dup2 onto itself", 50, dup2(50, 50));
	check_errno("dup3 onto itself EINVAL", dup3(50, 50, 0), EINVAL);
	check_errno("dup2 of a closed descriptor EBADF", dup2(77, 78), EBADF);
	check_eq("F_DUPFD answers the lowest free at or above 60", 60, fcntl(fd, F_DUPFD, 60));
	check_eq("F_DUPFD_CLOEXEC", 61, fcntl(fd, F_DUPFD_CLOEXEC, 60));
	check_eq("F_GETFD of F_DUPFD_CLOEXEC's descriptor", FD_CLOEXEC, fcntl(61, F_GETFD));
	check_eq("F_GETFD of dup's descriptor", 0, fcntl(60, F_GETFD));
	check_eq("F_SETFD", 0, fcntl(60, F_SETFD, FD_CLOEXEC));
	check_eq("F_GETFD after F_SETFD", FD_CLOEXEC, fcntl(60, F_GETFD));
	check_eq("F_GETFL of a read-only file", O_RDONLY, fcntl(fd, F_GETFL) & O_ACCMODE);
	check_errno("fcntl with a bad command EINVAL", fcntl(fd, 0x7fff), EINVAL);
	check_errno("fcntl of a closed descriptor EBADF", fcntl(77, F_GETFD), EBADF);
	close(d);
	close(50);
	close(60);
	close(61);

	/* Bad descriptors. */
	check_errno("read of a closed descriptor EBADF", read(77, buf, 1), EBADF);
	check_errno("read of a negative descriptor EBADF", read(-1, buf, 1), EBADF);
	check_errno("write to a read-only file EBADF", write(fd, "x", 1), EBADF);
	check_errno("close of a closed descriptor EBADF", close(77), EBADF);
	lseek(fd, 0, SEEK_SET);
	check_errno("read into a bad buffer EFAULT", syscall(SYS_read, fd, (void *)8, 1), EFAULT);
	check_eq("close", 0, close(fd));
	check_errno("close twice EBADF", close(fd), EBADF);

	/* Path errors. */
	check_errno("open of a missing file ENOENT", open("/nonexistent", O_RDONLY), ENOENT);
	check_errno("open below a file ENOTDIR", open("/etc/passwd/x", O_RDONLY), ENOTDIR);
	check_errno("open of a directory for writing EISDIR", open("/etc", O_WRONLY), EISDIR);
	check_errno("open O_DIRECTORY of a file ENOTDIR",
		    open("/etc/passwd", O_RDONLY | O_DIRECTORY), ENOTDIR);
	check_errno("open of an empty path ENOENT", open("", O_RDONLY), ENOENT);
	check_errno("open with a bad path pointer EFAULT",
		    syscall(SYS_open, (char *)8, O_RDONLY), EFAULT);
	check_errno("stat of a missing file ENOENT", stat("/nonexistent", &st), ENOENT);
	check_errno("access of a missing file ENOENT", access("/nonexistent", F_OK), ENOENT);
	check_eq("access R_OK of /etc/passwd", 0, access("/etc/passwd", R_OK));
	check_errno("readlink of a regular file EINVAL", readlink("/etc/passwd", buf, sizeof buf),
		    EINVAL);

	/* Directories. */
	int dir = open("/etc", O_RDONLY | O_DIRECTORY);
	check_ok("open /etc O_DIRECTORY", dir);
	check_errno("read of a directory EISDIR", read(dir, buf, 1), EISDIR);
	int rel = openat(dir, "passwd", O_RDONLY);
	check_ok("openat relative to a directory", rel);
	check_eq("openat's file reads", 5, read(rel, buf, 5));
	check("openat's file is the same", memcmp(buf, "root:", 5) == 0, "expected root:");
	check_errno("getdents64 of a file ENOTDIR", syscall(SYS_getdents64, rel, buf, sizeof buf),
		    ENOTDIR);
	check_errno("openat relative to a file ENOTDIR", openat(rel, "x", O_RDONLY), ENOTDIR);
	close(rel);
	check_eq("fstatat relative to a directory", 0, fstatat(dir, "passwd", &st, 0));
	check("stat /etc says directory", stat("/etc", &st) == 0 && S_ISDIR(st.st_mode),
	      "expected S_IFDIR");
	const char *etc_names[] = { ".", "..", "passwd" };
	check("getdents64 lists . .. passwd in /etc", lists(dir, etc_names, 3),
	      "expected all three names");
	check_eq("getdents64 at the end gives 0", 0, syscall(SYS_getdents64, dir, buf, sizeof buf));
	check_errno("getdents64 into a too small buffer EINVAL",
		    (lseek(dir, 0, SEEK_SET), syscall(SYS_getdents64, dir, buf, 8)), EINVAL);
	close(dir);
	int root = open("/", O_RDONLY | O_DIRECTORY);
	const char *root_names[] = { "bin", "etc", "tmp", "proc", "dev" };
	check("getdents64 lists bin etc tmp proc dev in /", lists(root, root_names, 5),
	      "expected all five names");
	close(root);

	/* The program itself: an executable regular file starting with the ELF magic. */
	fd = open(self_path, O_RDONLY);
	check_ok("open own executable", fd);
	check("own executable starts with the ELF magic",
	      read(fd, buf, 4) == 4 && memcmp(buf, "\177ELF", 4) == 0, "expected \\177ELF");
	check("own executable has the x bit", fstat(fd, &st) == 0 && (st.st_mode & 0100),
	      "expected mode with 0100");
	close(fd);

	/* close_range (glibc's closefrom): closes a range, or marks it close-on-exec. */
	int a = open("/etc/passwd", O_RDONLY), b = dup(a), c = dup(a);
	check_eq("close_range CLOSE_RANGE_CLOEXEC", 0,
		 syscall(SYS_close_range, b, c, CLOSE_RANGE_CLOEXEC));
	check("close_range CLOSE_RANGE_CLOEXEC keeps them open with FD_CLOEXEC",
	      fcntl(b, F_GETFD) == FD_CLOEXEC && fcntl(c, F_GETFD) == FD_CLOEXEC &&
		      fcntl(a, F_GETFD) == 0,
	      "expected FD_CLOEXEC on both, not on the first");
	check_eq("close_range", 0, syscall(SYS_close_range, b, ~0u, 0));
	check("close_range closed the range only",
	      fcntl(b, F_GETFD) == -1 && fcntl(c, F_GETFD) == -1 && fcntl(a, F_GETFD) == 0,
	      "expected the two closed, the first open");
	check_errno("close_range with first > last EINVAL", syscall(SYS_close_range, 5, 4, 0),
		    EINVAL);
	check_errno("close_range with an unknown flag EINVAL",
		    syscall(SYS_close_range, b, c, 1 << 8), EINVAL);
	close(a);

	/* As many descriptors as RLIMIT_NOFILE's soft limit allows, set below any hard one. */
	struct rlimit old_limit, limit = { 200, 200 };
	getrlimit(RLIMIT_NOFILE, &old_limit);
	limit.rlim_max = old_limit.rlim_max;
	check_eq("setrlimit RLIMIT_NOFILE 200", 0, setrlimit(RLIMIT_NOFILE, &limit));
	int high = 0;
	for (int i = 0; i < 150; i++)
		high = dup(0);
	check("150 more descriptors", high >= 150, "expected a descriptor above 149 got %d", high);
	check_eq("dup2 to descriptor 199", 199, dup2(0, 199));
	check_errno("dup2 to descriptor 200 EBADF", dup2(0, 200), EBADF);
	check_errno("F_DUPFD from the limit EINVAL", fcntl(0, F_DUPFD, 200), EINVAL);
	syscall(SYS_close_range, 3, ~0u, 0);
	setrlimit(RLIMIT_NOFILE, &old_limit);

	/* /proc/self/fd and /dev/fd (bash's <(...), glibc's closefrom): a link per descriptor;
	 * opening one opens what the descriptor has. */
	int ends[2], file = open("/etc/passwd", O_RDONLY);
	pipe(ends);
	char path[64], target[64];
	snprintf(path, sizeof path, "/proc/self/fd/%d", file);
	n = readlink(path, target, sizeof target - 1);
	target[n > 0 ? n : 0] = 0;
	check("readlink /proc/self/fd/N of a file gives its path", strcmp(target, "/etc/passwd") == 0,
	      "expected /etc/passwd got %s", target);
	snprintf(path, sizeof path, "/proc/self/fd/%d", ends[0]);
	n = readlink(path, target, sizeof target - 1);
	target[n > 0 ? n : 0] = 0;
	check("readlink /proc/self/fd/N of a pipe gives pipe:[...]",
	      strncmp(target, "pipe:[", 6) == 0, "expected pipe:[...] got %s", target);
	snprintf(path, sizeof path, "/dev/fd/%d", ends[0]);
	int reader = open(path, O_RDONLY);
	check_ok("open /dev/fd/N of a pipe", reader);
	write(ends[1], "fd", 2);
	check("/dev/fd/N reads the pipe", read(reader, buf, 8) == 2 && memcmp(buf, "fd", 2) == 0,
	      "expected the 2 bytes written");
	snprintf(path, sizeof path, "/dev/fd/%d", file);
	int again = open(path, O_RDONLY);
	lseek(file, 5, SEEK_SET);
	check_eq("a file opened through /dev/fd/N has its own offset", 0, lseek(again, 0, SEEK_CUR));
	DIR *fds = opendir("/proc/self/fd");
	int seen = 0;
	for (struct dirent *e; fds && (e = readdir(fds));)
		seen += atoi(e->d_name) == reader;
	check("/proc/self/fd lists an open descriptor", seen == 1, "expected it once got %d", seen);
	if (fds)
		closedir(fds);
	snprintf(path, sizeof path, "/proc/self/fd/%d", again + 1);
	check_errno("open /proc/self/fd/N of a closed descriptor ENOENT", open(path, O_RDONLY),
		    ENOENT);
	syscall(SYS_close_range, 3, ~0u, 0);
}
