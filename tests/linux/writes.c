/* Area `writes`: files written in a fresh directory under /tmp: creating (O_CREAT, O_EXCL,
 * O_TRUNC, O_APPEND, the umask), write, pwrite, lseek past the end (holes), ftruncate,
 * rename, unlink, mkdir, rmdir, getdents64 of what was created, and their errors EEXIST,
 * ENOENT, ENOTEMPTY, EISDIR, ENOTDIR. Everything it creates it removes. */
#include "check.h"

#include <dirent.h>
#include <fcntl.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/syscall.h>

static char dir[64];

static const char *at(const char *name)
{
	static char path[2][128];
	static int which;
	which ^= 1;
	snprintf(path[which], sizeof path[which], "%s/%s", dir, name);
	return path[which];
}

/* The names getdents64 lists in `path` besides . and .., sorted and joined by spaces. */
static void names_in(const char *path, char *out, size_t size)
{
	char buf[4096], names[16][64];
	int count = 0;
	long n;
	int fd = open(path, O_RDONLY | O_DIRECTORY);
	out[0] = 0;
	if (fd < 0)
		return;
	while ((n = syscall(SYS_getdents64, fd, buf, sizeof buf)) > 0)
		for (long off = 0; off < n;) {
			struct dirent64 *d = (struct dirent64 *)(buf + off);
			if (strcmp(d->d_name, ".") && strcmp(d->d_name, "..") && count < 16)
				snprintf(names[count++], 64, "%.63s", d->d_name);
			off += d->d_reclen;
		}
	close(fd);
	qsort(names, count, 64, (int (*)(const void *, const void *))strcmp);
	for (int i = 0; i < count; i++) {
		strncat(out, names[i], size - strlen(out) - 1);
		if (i + 1 < count)
			strncat(out, " ", size - strlen(out) - 1);
	}
}

void area_writes(void)
{
	char buf[64];
	struct stat st;
	snprintf(dir, sizeof dir, "/tmp/linux-tests-XXXXXX");
	char *made = mkdtemp(dir);
	check("mkdtemp under /tmp", made != NULL, "expected success got %s", errno_name(errno));
	mode_t old_mask = umask(022);

	int fd = open(at("a"), O_RDWR | O_CREAT | O_EXCL, 0666);
	check_ok("open O_CREAT|O_EXCL", fd);
	if (fd < 0) {
		umask(old_mask);
		rmdir(dir);
		return;
	}
	check("new file's mode is 0666 less the umask 022",
	      fstat(fd, &st) == 0 && (st.st_mode & 07777) == 0644 && S_ISREG(st.st_mode),
	      "expected 0644 got 0%o", st.st_mode & 07777);
	check_eq("new file is empty", 0, st.st_size);
	check_errno("O_EXCL on an existing file EEXIST",
		    open(at("a"), O_RDWR | O_CREAT | O_EXCL, 0666), EEXIST);
	check_eq("write 11 bytes", 11, write(fd, "hello world", 11));
	check_eq("offset after write", 11, lseek(fd, 0, SEEK_CUR));
	check_eq("pwrite at 6", 5, pwrite(fd, "WORLD", 5, 6));
	check_eq("pwrite leaves the offset", 11, lseek(fd, 0, SEEK_CUR));
	check_eq("pread what was written", 11, pread(fd, buf, 11, 0));
	check("file holds the bytes written", memcmp(buf, "hello WORLD", 11) == 0,
	      "expected hello WORLD got %.11s", buf);
	check("fstat size after writes", fstat(fd, &st) == 0 && st.st_size == 11,
	      "expected 11 got %ld", (long)st.st_size);

	/* A write past the end leaves a hole of zeroes. */
	check_eq("lseek past the end", 20, lseek(fd, 20, SEEK_SET));
	check_eq("write after the hole", 1, write(fd, "!", 1));
	memset(buf, 'x', sizeof buf);
	check_eq("read across the hole", 10, pread(fd, buf, 10, 11));
	check("hole reads as zeroes then the byte",
	      buf[0] == 0 && buf[8] == 0 && buf[9] == '!', "expected 9 zero bytes then !");

	check_eq("ftruncate to 5", 0, ftruncate(fd, 5));
	check("size after ftruncate", fstat(fd, &st) == 0 && st.st_size == 5, "expected 5 got %ld",
	      (long)st.st_size);
	check_eq("read at an offset beyond the end gives 0", 0, pread(fd, buf, 4, 10));
	close(fd);

	/* O_APPEND writes at the end whatever the offset; O_TRUNC empties. */
	fd = open(at("a"), O_WRONLY | O_APPEND);
	lseek(fd, 0, SEEK_SET);
	check_eq("O_APPEND write", 3, write(fd, "abc", 3));
	check_eq("O_APPEND wrote at the end", 8, lseek(fd, 0, SEEK_CUR));
	check_errno("read of a write-only file EBADF", read(fd, buf, 1), EBADF);
	close(fd);
	fd = open(at("a"), O_RDONLY);
	check("file after append", read(fd, buf, 8) == 8 && memcmp(buf, "helloabc", 8) == 0,
	      "expected helloabc");
	close(fd);
	fd = open(at("a"), O_RDWR | O_TRUNC);
	check("O_TRUNC empties the file", fstat(fd, &st) == 0 && st.st_size == 0,
	      "expected size 0");
	close(fd);

	/* Directories and names. */
	check_eq("mkdir", 0, mkdir(at("sub"), 0755));
	check_errno("mkdir of an existing name EEXIST", mkdir(at("sub"), 0755), EEXIST);
	check_errno("mkdir below a missing directory ENOENT", mkdir(at("none/sub"), 0755), ENOENT);
	check_errno("open O_CREAT below a file ENOTDIR", open(at("a/x"), O_CREAT | O_RDWR, 0644),
		    ENOTDIR);
	check_errno("open O_CREAT of a directory EISDIR", open(at("sub"), O_CREAT | O_RDWR, 0644),
		    EISDIR);
	fd = open(at("sub/b"), O_CREAT | O_WRONLY, 0600);
	check_ok("create a file in the subdirectory", fd);
	close(fd);
	check_eq("rename a file", 0, rename(at("a"), at("c")));
	check_errno("the old name is gone", stat(at("a"), &st), ENOENT);
	char names[256];
	names_in(dir, names, sizeof names);
	check("getdents64 lists the created names", strcmp(names, "c sub") == 0,
	      "expected \"c sub\" got \"%s\"", names);
	check_errno("rmdir of a non-empty directory ENOTEMPTY", rmdir(at("sub")), ENOTEMPTY);
	check_errno("unlink of a directory EISDIR", unlink(at("sub")), EISDIR);
	check_errno("rmdir of a file ENOTDIR", rmdir(at("c")), ENOTDIR);
	check_errno("unlink of a missing file ENOENT", unlink(at("missing")), ENOENT);

	/* An unlinked file stays readable through an open descriptor. */
	fd = open(at("c"), O_RDWR);
	write(fd, "kept", 4);
	check_eq("unlink", 0, unlink(at("c")));
	check_errno("stat of the unlinked name ENOENT", stat(at("c"), &st), ENOENT);
	check("an open unlinked file still reads", pread(fd, buf, 4, 0) == 4 &&
							  memcmp(buf, "kept", 4) == 0,
	      "expected kept");
	close(fd);
	check_eq("unlink in the subdirectory", 0, unlink(at("sub/b")));
	check_eq("rmdir of the empty subdirectory", 0, rmdir(at("sub")));
	check_eq("rmdir of the test directory", 0, rmdir(dir));
	umask(old_mask);
}
