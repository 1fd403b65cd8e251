/* A Linux test program for the guest's memory and fault handling (built by `cargo xtask`
 * with `gcc -static`, see xtask/src/guest_programs.rs). `probe <what>` does one thing that
 * must kill it with a signal (it prints "<what>: not contained" and exits 1 if it lives
 * on); `probe memory` checks demand paging, copy-on-write fork, mprotect, munmap,
 * madvise, mremap and mmap and prints "memory: <check> ok" for each (exit 0 when all passed);
 * `probe threads` is a thread bomb: it creates threads that sleep until pthread_create
 * fails, prints "threads: <n> created, then <error>" and exits (ending them all). */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

static int failures;

static void check(int ok, const char *what) {
    printf("memory: %s %s\n", what, ok ? "ok" : "FAILED");
    if (!ok)
        failures++;
}

/* Not inlined: the compiler must not see (and refuse) the constant bad addresses. */
static __attribute__((noinline)) int read_at(uintptr_t address) { return *(volatile int *)address; }

static uint8_t in_port(uint16_t port) {
    uint8_t v;
    __asm__ volatile("inb %1, %0" : "=a"(v) : "Nd"(port));
    return v;
}

static void out_port(uint16_t port, uint8_t v) {
    __asm__ volatile("outb %0, %1" : : "a"(v), "Nd"(port));
}

/* The wait status of a child that runs `f(arg)`. */
static int in_child(void (*f)(uintptr_t), uintptr_t arg) {
    pid_t pid = fork();
    if (pid == 0) {
        f(arg);
        _exit(0);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    return status;
}

static void write_byte(uintptr_t address) { *(volatile char *)address = 1; }

static int memory(void) {
    /* Demand paging: a large anonymous mapping costs nothing until touched. */
    size_t len = 64 << 20;
    char *big = mmap(NULL, len, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    check(big != MAP_FAILED, "mmap of 64 MiB (backed on demand)");
    big[0] = 'a';
    big[len - 1] = 'z';
    check(big[0] == 'a' && big[len - 1] == 'z' && big[len / 2] == 0, "touched pages");
    check(madvise(big + len - 4096, 4096, MADV_DONTNEED) == 0 && big[len - 1] == 0,
          "MADV_DONTNEED gives zeros");

    /* The heap: malloc of small and large blocks. */
    char *heap = malloc(1 << 20);
    memset(heap, 'h', 1 << 20);
    check(heap[12345] == 'h', "malloc and memset of 1 MiB");

    /* Copy-on-write: the child's writes stay its own, the parent's too. */
    strcpy(heap, "parent");
    strcpy(big, "parent");
    int pipefd[2];
    pipe(pipefd);
    pid_t pid = fork();
    if (pid == 0) {
        int ok = strcmp(heap, "parent") == 0;
        strcpy(heap, "child");
        big[1] = 'C';
        /* A read() into a shared page: the guest writes into it for the child. */
        char buf[8] = {0};
        read(pipefd[0], big + 100, 5);
        memcpy(buf, big + 100, 5);
        ok = ok && strcmp(heap, "child") == 0 && strcmp(buf, "bytes") == 0;
        _exit(ok ? 0 : 1);
    }
    write(pipefd[1], "bytes", 5);
    int status = 0;
    waitpid(pid, &status, 0);
    check(WIFEXITED(status) && WEXITSTATUS(status) == 0, "the child saw its own copy");
    check(strcmp(heap, "parent") == 0 && big[1] == 'a' && big[100] == 0,
          "the parent kept its pages");
    strcpy(heap, "again");
    check(strcmp(heap, "again") == 0, "the parent writes after the child ended");

    /* mprotect on part of an area: a write there is SIGSEGV, the rest stays writable. */
    char *area = mmap(NULL, 4 * 4096, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    area[4096] = 'x';
    check(mprotect(area + 4096, 4096, PROT_READ) == 0, "mprotect of one page");
    status = in_child(write_byte, (uintptr_t)(area + 4096));
    check(WIFSIGNALED(status) && WTERMSIG(status) == SIGSEGV, "a write to it is SIGSEGV");
    area[0] = 'y';
    area[2 * 4096] = 'y';
    check(area[4096] == 'x', "its contents stayed");
    check(mprotect(area + 4096, 4096, PROT_READ | PROT_WRITE) == 0 && (area[4096] = 'w') == 'w',
          "writable again");

    /* munmap of the middle: a read there is SIGSEGV. */
    check(munmap(area + 4096, 4096) == 0, "munmap of one page");
    status = in_child((void (*)(uintptr_t))read_at, (uintptr_t)(area + 4096));
    check(WIFSIGNALED(status) && WTERMSIG(status) == SIGSEGV, "a read there is SIGSEGV");
    check(area[2 * 4096] == 'y', "the pages around it stayed");

    /* MAP_FIXED replaces, MAP_FIXED_NOREPLACE refuses. */
    char *fixed = mmap(area, 4096, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED, -1, 0);
    check(fixed == area && area[0] == 0, "MAP_FIXED replaced a page");
    char *no = mmap(area, 4096, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED_NOREPLACE, -1, 0);
    check(no == MAP_FAILED, "MAP_FIXED_NOREPLACE refused (EEXIST)");

    /* mremap: grown (moved if it must be), contents kept. */
    char *small = mmap(NULL, 4096, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    strcpy(small, "kept");
    char *grown = mremap(small, 4096, 1 << 20, MREMAP_MAYMOVE);
    check(grown != MAP_FAILED && strcmp(grown, "kept") == 0 && grown[(1 << 20) - 1] == 0,
          "mremap kept the contents");

    /* A file mapping. */
    int fd = open("/etc/passwd", O_RDONLY);
    char *file = mmap(NULL, 4096, PROT_READ, MAP_PRIVATE, fd, 0);
    check(file != MAP_FAILED && strncmp(file, "root:", 5) == 0, "mmap of /etc/passwd");

    printf("memory: %s\n", failures ? "FAILED" : "all checks passed");
    return failures ? 1 : 0;
}

static void *sleeper(void *arg) {
    (void)arg;
    for (;;)
        pause();
    return NULL;
}

/* The thread bomb: threads until the system refuses one (at most 100,000). */
static int thread_bomb(void) {
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    pthread_attr_setstacksize(&attr, 64 * 1024);
    int n = 0, error = 0;
    while (n < 100000) {
        pthread_t t;
        error = pthread_create(&t, &attr, sleeper, NULL);
        if (error != 0)
            break;
        n++;
    }
    printf("threads: %d created, then %s\n", n,
           error == EAGAIN ? "EAGAIN" : error == 0 ? "none refused" : strerror(error));
    fflush(stdout);
    exit(0);
}

int main(int argc, char **argv) {
    const char *what = argc > 1 ? argv[1] : "";
    if (strcmp(what, "memory") == 0)
        return memory();
    if (strcmp(what, "threads") == 0)
        return thread_bomb();
    if (strcmp(what, "segv") == 0)
        read_at(16);
    else if (strcmp(what, "ill") == 0)
        __asm__ volatile("ud2");
    else if (strcmp(what, "div") == 0) {
        volatile int zero = 0, n = 100;
        printf("%d\n", n / zero);
    } else if (strcmp(what, "stack") == 0) {
        /* Below the stack's area (the guest's stack does not grow): its guard. */
        char here;
        read_at((uintptr_t)&here - (1 << 20));
    } else if (strcmp(what, "kernel") == 0)
        read_at(0xffff800000000000ull);
    else if (strcmp(what, "pool") == 0)
        read_at(0x580000000000ull); /* the guest's own frames */
    else if (strcmp(what, "data") == 0)
        read_at(0x500000000000ull); /* the guest's initramfs */
    else if (strcmp(what, "port") == 0)
        in_port(0x3f8); /* COM1: the kernel's */
    else if (strcmp(what, "console") == 0)
        in_port(0x2f8); /* COM2: the guest's, not its processes' */
    else if (strcmp(what, "exit") == 0)
        out_port(0xf4, 0); /* QEMU's exit device */
    else if (strcmp(what, "cli") == 0)
        __asm__ volatile("cli");
    else if (strcmp(what, "enosys") == 0) {
        /* A call the guest does not serve (io_uring_setup): ENOSYS, logged once per guest. */
        long r = syscall(SYS_io_uring_setup, 1, 0);
        printf("enosys: %s\n", r == -1 && errno == ENOSYS ? "ENOSYS" : "served");
        return 0;
    } else {
        printf("usage: probe memory|threads|segv|ill|div|stack|kernel|pool|data|port|console|exit|cli|enosys\n");
        return 2;
    }
    printf("%s: not contained\n", what);
    return 1;
}
