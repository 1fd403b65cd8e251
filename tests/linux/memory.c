/* Area `memory`: brk, anonymous mmap (plain, fixed, hinted, large and untouched), private
 * file mappings, munmap and mprotect with their errors, the SIGSEGV a child gets for
 * touching memory it has not (or no longer, or not writable), and vfork's child borrowing
 * its parent's memory; mlock, munlock, mlockall's errors and munlockall. */
#include "check.h"

#include <fcntl.h>
#include <signal.h>
#include <stdint.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <sys/wait.h>

#define PAGE 4096L

/* Runs `touch(address)` in a child without core dump and returns its wait status. */
static int in_child(void (*touch)(volatile char *), volatile char *address)
{
	int pid = fork();
	if (pid == 0) {
		struct rlimit none = { 0, 0 };
		setrlimit(RLIMIT_CORE, &none);
		touch(address);
		_exit(0);
	}
	return wait_for(pid);
}

static void write_byte(volatile char *p)
{
	*p = 1;
}

static void read_byte(volatile char *p)
{
	if (*p == 123)
		_exit(3);
}

/* Expects mmap's answer `ret` to be MAP_FAILED with errno `expected`. */
static void check_map_errno(const char *name, void *ret, int expected)
{
	int e = errno;
	if (ret != MAP_FAILED)
		check(name, 0, "expected %s got a mapping", errno_name(expected));
	else
		check(name, e == expected, "expected %s got %s", errno_name(expected), errno_name(e));
}

static int all_zero(const char *p, long len)
{
	for (long i = 0; i < len; i++)
		if (p[i])
			return 0;
	return 1;
}

void area_memory(void)
{
	/* brk: the raw call answers the current break, grows it, shrinks it. */
	long start = syscall(SYS_brk, 0);
	check("brk(0) answers the break", start > 0, "expected an address");
	long grown = syscall(SYS_brk, start + 16 * PAGE);
	check_eq("brk grows the heap", start + 16 * PAGE, grown);
	if (grown == start + 16 * PAGE) {
		char *heap = (char *)start;
		check("grown heap is zeroed", all_zero(heap, 16 * PAGE), "expected zero bytes");
		heap[0] = 1;
		heap[16 * PAGE - 1] = 2;
		check("grown heap is writable", heap[0] == 1 && heap[16 * PAGE - 1] == 2,
		      "expected the bytes written");
	}
	check_eq("brk shrinks the heap", start, syscall(SYS_brk, start));
	check_eq("brk below the start is refused (answers the break)", start,
		 syscall(SYS_brk, 4096));

	/* Anonymous mappings. */
	char *a = mmap(NULL, 4 * PAGE, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
	check("mmap anonymous", a != MAP_FAILED, "expected success got %s", errno_name(errno));
	if (a == MAP_FAILED)
		return;
	check_eq("mmap answers a page-aligned address", 0, (long)((uintptr_t)a % PAGE));
	check("anonymous mapping is zeroed", all_zero(a, 4 * PAGE), "expected zero bytes");
	a[0] = 'x';
	a[4 * PAGE - 1] = 'y';
	check("anonymous mapping is writable", a[0] == 'x' && a[4 * PAGE - 1] == 'y',
	      "expected the bytes written");
	check_map_errno("mmap of length 0 EINVAL",
			mmap(NULL, 0, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0), EINVAL);
	check_map_errno("mmap without MAP_PRIVATE or MAP_SHARED EINVAL",
			mmap(NULL, PAGE, PROT_READ, MAP_ANONYMOUS, -1, 0), EINVAL);
	check_map_errno("mmap of a bad descriptor EBADF",
			mmap(NULL, PAGE, PROT_READ, MAP_PRIVATE, 999, 0), EBADF);
	check_map_errno("mmap MAP_FIXED at an unaligned address EINVAL",
			mmap(a + 1, PAGE, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED, -1, 0),
			EINVAL);

	/* MAP_FIXED replaces what is there; the hole munmap leaves can be filled again. */
	check_eq("munmap of the second page", 0, munmap(a + PAGE, PAGE));
	check_status("touching an unmapped page kills with SIGSEGV",
		     in_child(write_byte, a + PAGE), -1, SIGSEGV);
	char *fixed = mmap(a + PAGE, PAGE, PROT_READ | PROT_WRITE,
			   MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED, -1, 0);
	check("mmap MAP_FIXED fills the hole", fixed == a + PAGE, "expected the address asked");
	if (fixed == a + PAGE)
		check("fixed page is zeroed and the others kept",
		      all_zero(fixed, PAGE) && a[0] == 'x' && a[4 * PAGE - 1] == 'y',
		      "expected zeroes and the old bytes");
	char *over = mmap(a, PAGE, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED,
			  -1, 0);
	check("mmap MAP_FIXED over a mapping replaces it", over == a && a[0] == 0,
	      "expected a fresh zero page at the address");
	check_eq("munmap of the whole range", 0, munmap(a, 4 * PAGE));
	check_eq("munmap of a range without mappings succeeds", 0, munmap(a, 4 * PAGE));
	check_errno("munmap at an unaligned address EINVAL", munmap(a + 1, PAGE), EINVAL);
	check_errno("munmap of length 0 EINVAL", munmap(a, 0), EINVAL);

	/* A free hint is taken as is. */
	char *hint = (char *)0x200000000L;
	char *hinted = mmap(hint, 2 * PAGE, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS,
			    -1, 0);
	check("mmap takes a free hint", hinted == hint, "expected the hint got another address");
	if (hinted != MAP_FAILED)
		munmap(hinted, 2 * PAGE);

	/* mprotect. */
	char *p = mmap(NULL, 2 * PAGE, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
	if (p != MAP_FAILED) {
		p[0] = 5;
		check_eq("mprotect to read-only", 0, mprotect(p, PAGE, PROT_READ));
		check_status("read-only page is still readable", in_child(read_byte, p), 0, 0);
		check_status("writing a read-only page kills with SIGSEGV", in_child(write_byte, p),
			     -1, SIGSEGV);
		check_status("the next page stays writable", in_child(write_byte, p + PAGE), 0, 0);
		check_eq("mprotect back to read-write", 0, mprotect(p, PAGE, PROT_READ | PROT_WRITE));
		p[0] = 6;
		check_eq("page writable again keeps its data", 6, p[0]);
		check_status("PROT_NONE page kills a reader with SIGSEGV",
			     (mprotect(p, PAGE, PROT_NONE), in_child(read_byte, p)), -1, SIGSEGV);
		check_errno("mprotect at an unaligned address EINVAL", mprotect(p + 1, PAGE, PROT_READ),
			    EINVAL);
		munmap(p, 2 * PAGE);
		check_errno("mprotect of unmapped memory ENOMEM", mprotect(p, PAGE, PROT_READ),
			    ENOMEM);
	}
	check_status("a null pointer write kills with SIGSEGV", in_child(write_byte, NULL), -1,
		     SIGSEGV);

	/* Private file mappings: the file's bytes, copy-on-write, the file unchanged. */
	int fd = open(self_path, O_RDONLY);
	check_ok("open own executable", fd);
	char *f = mmap(NULL, 2 * PAGE, PROT_READ | PROT_WRITE, MAP_PRIVATE, fd, 0);
	check("mmap of a file private", f != MAP_FAILED, "expected success got %s",
	      errno_name(errno));
	if (f != MAP_FAILED) {
		check("file mapping holds the file", memcmp(f, "\177ELF", 4) == 0,
		      "expected the ELF magic");
		f[0] = 'X';
		char first = 0;
		check_eq("pread after writing the private mapping", 1, pread(fd, &first, 1, 0));
		check_eq("file unchanged by a private mapping's write", 0x7f, first);
		munmap(f, 2 * PAGE);
	}
	char *g = mmap(NULL, PAGE, PROT_READ, MAP_PRIVATE, fd, PAGE);
	if (g != MAP_FAILED) {
		char page[16];
		pread(fd, page, sizeof page, PAGE);
		check("file mapping at an offset", memcmp(g, page, sizeof page) == 0,
		      "expected the bytes at the offset");
		munmap(g, PAGE);
	} else {
		check("file mapping at an offset", 0, "expected success got %s", errno_name(errno));
	}
	check_map_errno("file mapping at an unaligned offset EINVAL",
			mmap(NULL, PAGE, PROT_READ, MAP_PRIVATE, fd, 1), EINVAL);
	close(fd);

	/* A vfork child runs in its parent's memory until it exits or executes. */
	static volatile int shared;
	shared = 0;
	int pid = vfork();
	if (pid == 0) {
		shared = 7;
		_exit(0);
	}
	wait_for(pid);
	check_eq("vfork child's write seen by the parent", 7, shared);

	/* A large mapping costs only what is touched (demand paging). */
	long big = 256L << 20;
	char *huge = mmap(NULL, big, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
	check("mmap of 256 MiB", huge != MAP_FAILED, "expected success got %s", errno_name(errno));
	if (huge != MAP_FAILED) {
		for (long off = 0; off < big; off += 64L << 20)
			huge[off] = 1;
		check("256 MiB mapping touched at four pages", huge[0] == 1 && huge[192L << 20] == 1,
		      "expected the bytes written");
		munmap(huge, big);
	}

	/* Memory locks: a page locks within any RLIMIT_MEMLOCK a system gives (8 MiB by
	 * default); an unmapped range or a bad flag fails as Linux says. */
	char *lockable = mmap(NULL, 2 * PAGE, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS,
			      -1, 0);
	check_eq("mlock of a page", 0, mlock(lockable + 1, PAGE - 1));
	check_eq("mlock of the same page again", 0, mlock(lockable, PAGE));
	check_eq("munlock", 0, munlock(lockable, 2 * PAGE));
	check_eq("mlock2 MLOCK_ONFAULT", 0, syscall(SYS_mlock2, lockable, PAGE, 1));
	check_errno("mlock2 with an unknown flag EINVAL", syscall(SYS_mlock2, lockable, PAGE, 2),
		    EINVAL);
	munmap(lockable, 2 * PAGE);
	check_errno("mlock of unmapped memory ENOMEM", mlock(lockable, PAGE), ENOMEM);
	check_errno("munlock of unmapped memory ENOMEM", munlock(lockable, PAGE), ENOMEM);
	check_errno("mlockall without MCL_CURRENT or MCL_FUTURE EINVAL", mlockall(MCL_ONFAULT),
		    EINVAL);
	check_eq("munlockall", 0, munlockall());
}
