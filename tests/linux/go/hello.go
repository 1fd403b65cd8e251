// Command go-hello exercises what a Go service asks of Linux: goroutines spread over
// threads, channels, sync.WaitGroup and sync.Mutex, timers (time.Sleep, time.After,
// time.Ticker), a select with a timeout, os.Getpid, files written and read back in a
// directory, /proc/self, a child process through os/exec, the garbage collector and
// asynchronous preemption. Scenario
// guest_go runs it in the guest and on the host and compares the output, so it prints no
// time, pid or address.
package main

import (
	"fmt"
	"os"
	"os/exec"
	"path/filepath"
	"runtime"
	"sort"
	"strings"
	"sync"
	"sync/atomic"
	"time"
)

func main() {
	dir := os.TempDir()
	if len(os.Args) > 1 {
		dir = os.Args[1]
	}
	fmt.Println("go: start")

	// Eight workers sum their share of 1..80000 under a mutex and send their ids.
	var (
		mu    sync.Mutex
		total int
		wg    sync.WaitGroup
	)
	done := make(chan int, 8)
	for w := 0; w < 8; w++ {
		wg.Add(1)
		go func(w int) {
			defer wg.Done()
			for i := w*10000 + 1; i <= (w+1)*10000; i++ {
				mu.Lock()
				total += i
				mu.Unlock()
				if i%2500 == 0 {
					runtime.Gosched()
				}
			}
			done <- w
		}(w)
	}
	wg.Wait()
	close(done)
	ids := []int{}
	for w := range done {
		ids = append(ids, w)
	}
	sort.Ints(ids)
	fmt.Println("workers:", ids, "total:", total)

	// A pipeline of unbuffered channels.
	in := make(chan int)
	out := make(chan int)
	go func() {
		for v := range in {
			out <- v * v
		}
		close(out)
	}()
	go func() {
		for i := 1; i <= 10; i++ {
			in <- i
		}
		close(in)
	}()
	squares := 0
	for v := range out {
		squares += v
	}
	fmt.Println("squares:", squares)

	// Timers: a sleep, a ticker and a select that times out.
	start := time.Now()
	time.Sleep(10 * time.Millisecond)
	fmt.Println("slept at least 10ms:", time.Since(start) >= 10*time.Millisecond)
	ticker := time.NewTicker(10 * time.Millisecond)
	ticks := 0
	for range ticker.C {
		ticks++
		if ticks == 3 {
			break
		}
	}
	ticker.Stop()
	fmt.Println("ticks:", ticks)
	never := make(chan int)
	select {
	case <-never:
		fmt.Println("select: value")
	case <-time.After(10 * time.Millisecond):
		fmt.Println("select: timeout")
	}
	timer := time.NewTimer(time.Hour)
	fmt.Println("timer stopped:", timer.Stop())

	// Many goroutines sleeping at once.
	var sleepers sync.WaitGroup
	woke := make(chan struct{}, 100)
	for i := 0; i < 100; i++ {
		sleepers.Add(1)
		go func(i int) {
			defer sleepers.Done()
			time.Sleep(time.Duration(i%5) * time.Millisecond)
			woke <- struct{}{}
		}(i)
	}
	sleepers.Wait()
	fmt.Println("sleepers woke:", len(woke))

	// The process and /proc/self.
	fmt.Println("pid positive:", os.Getpid() > 0)
	stat, err := os.ReadFile("/proc/self/stat")
	if err != nil {
		fail("read /proc/self/stat", err)
	}
	fields := strings.Fields(string(stat))
	fmt.Println("/proc/self/stat pid matches:", len(fields) > 2 && fields[0] == fmt.Sprint(os.Getpid()))
	exe, err := os.Readlink("/proc/self/exe")
	if err != nil {
		fail("readlink /proc/self/exe", err)
	}
	fmt.Println("exe:", filepath.Base(exe))

	// Files written by goroutines and read back.
	path := filepath.Join(dir, "go-hello.txt")
	f, err := os.Create(path)
	if err != nil {
		fail("create", err)
	}
	var fmu sync.Mutex
	var writers sync.WaitGroup
	for i := 0; i < 4; i++ {
		writers.Add(1)
		go func(i int) {
			defer writers.Done()
			fmu.Lock()
			defer fmu.Unlock()
			fmt.Fprintf(f, "line %d\n", i)
		}(i)
	}
	writers.Wait()
	if err := f.Close(); err != nil {
		fail("close", err)
	}
	data, err := os.ReadFile(path)
	if err != nil {
		fail("read back", err)
	}
	lines := strings.Split(strings.TrimSpace(string(data)), "\n")
	sort.Strings(lines)
	fmt.Println("file:", strings.Join(lines, ","))
	if err := os.Remove(path); err != nil {
		fail("remove", err)
	}
	_, err = os.Stat(path)
	fmt.Println("removed:", os.IsNotExist(err))

	// A child process through os/exec (fork, execve, pipes, wait): its output and its
	// exit status.
	said, err := exec.Command("busybox", "echo", "from", "a", "child").Output()
	if err != nil {
		fail("exec busybox echo", err)
	}
	fmt.Print("child said: ", string(said))
	err = exec.Command("busybox", "false").Run()
	exit, ok := err.(*exec.ExitError)
	fmt.Println("child false exits 1:", ok && exit.ExitCode() == 1)

	// The garbage collector with goroutines allocating.
	var allocs sync.WaitGroup
	sums := make([]int, 4)
	for g := 0; g < 4; g++ {
		allocs.Add(1)
		go func(g int) {
			defer allocs.Done()
			for i := 0; i < 2000; i++ {
				b := make([]byte, 1024)
				b[i%1024] = 1
				sums[g] += int(b[i%1024])
			}
		}(g)
	}
	allocs.Wait()
	runtime.GC()
	fmt.Println("allocated:", sums)

	// Asynchronous preemption: on one P, a goroutine spinning without a call yields only
	// when the runtime interrupts its thread (SIGURG by tgkill, a handler that rewrites
	// the interrupted context, rt_sigreturn), so the main goroutine gets to stop it.
	previous := runtime.GOMAXPROCS(1)
	var stop atomic.Bool
	spun := make(chan struct{})
	go func() {
		for !stop.Load() {
		}
		close(spun)
	}()
	time.Sleep(time.Millisecond)
	runtime.Gosched()
	stop.Store(true)
	<-spun
	runtime.GOMAXPROCS(previous)
	fmt.Println("spinning goroutine preempted: true")

	fmt.Println("go: done")
}

func fail(what string, err error) {
	fmt.Println("FAIL", what+":", err)
	os.Exit(1)
}
