//! Kernel entry and exit for user threads.
//!
//! Every entry from ring 3 (`syscall`, interrupt, exception) leaves the same [`TrapFrame`]
//! in the same place: the running thread's own saved context, which the CPU's
//! [`CpuEntry::active_frame`] points to (and the TSS's ring-0 stack pointer just past it,
//! so the CPU pushes an interrupt's part of the frame there too). The stubs then switch to
//! the CPU's kernel stack for the portable code, which decides, and return through the
//! frame `active_frame` then points to: switching threads copies no registers. The stubs
//! find their CPU's [`CpuEntry`] through GS: in kernel mode GS's base is that block, in
//! user mode the running thread's (`swapgs` on every entry from and exit to ring 3). A
//! `syscall` entry returns with `sysret` when the frame allows it (`rcx` = `rip`, `r11` =
//! `rflags`, as for any thread that entered by `syscall`), else with `iretq`, which
//! restores every register.
//!
//! With nothing to run the CPU halts with interrupts enabled *inside* the exit path; an
//! interrupt then arrives in ring 0 on the kernel stack, updates the kernel state and
//! returns to the halt loop, which looks again.
//!
//! Every CPU runs this path; the kernel's objects are behind one lock ([`KERNEL`], taken
//! once per entry, interrupts off, every path under it bounded). Before it lets go, the
//! CPU sends an interrupt ([`idt::RESCHEDULE_VECTOR`](super::idt::RESCHEDULE_VECTOR)) to
//! each other CPU whose state it changed (`Kernel::cpus_to_kick`), and one waiting for the
//! lock answers address-space requests meanwhile (`smp::serve_space_request`), since the
//! holder may be waiting for that answer.

use super::gdt::TssBlock;
use super::idt::TrapFrame;
use crate::state::Kernel;
use crate::syscall::Outcome;
use crate::table::{TaskIdx, ThreadIdx};
use crate::{fault, qemu, time};
use core::arch::naked_asm;
use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use spin::{Mutex, MutexGuard};

/// The kernel's objects. Locked once per entry ([`lock_kernel`]); never held while halting.
pub static KERNEL: Mutex<Kernel> = Mutex::new(Kernel::new());

/// Size of the user frame at the top of the kernel stack.
pub const FRAME_SIZE: usize = core::mem::size_of::<TrapFrame>();

/// Set once user mode runs; before that, timer interrupts only count (boot calibration).
static RUNNING: AtomicBool = AtomicBool::new(false);

/// What one CPU's entry stubs keep and find through GS (its kernel-mode base).
#[repr(C)]
pub(super) struct CpuEntry {
    /// This block's address (what `gs:[0]` gives the portable code).
    this: u64,
    /// The CPU's number (0: the boot CPU).
    number: u64,
    /// Its TSS block, whose ring-0 stack pointer follows the active frame and whose I/O
    /// bitmap is the running task's.
    tss: u64,
    /// A `syscall`'s user stack pointer, until the frame holds it.
    user_rsp: u64,
    /// The running thread's saved context: where the stubs save a user frame and what
    /// they return through. Written only by [`activate_frame`] (interrupts off).
    pub(super) active_frame: u64,
    /// The top of this CPU's kernel stack.
    pub(super) stack_top: u64,
}

static mut CPU_ENTRIES: [CpuEntry; abi::machine::MAX_CPUS] = [const {
    CpuEntry {
        this: 0,
        number: 0,
        tss: 0,
        user_rsp: 0,
        active_frame: 0,
        stack_top: 0,
    }
}; abi::machine::MAX_CPUS];

const IA32_GS_BASE: u32 = 0xc000_0101;

/// Makes entry block `cpu` this CPU's (its GS base), with its kernel stack's top and TSS.
pub(super) fn init_cpu(cpu: usize, stack_top: u64, tss: *mut TssBlock) {
    // SAFETY: only the address of the block is taken.
    let block = unsafe { &raw mut CPU_ENTRIES[cpu] };
    // SAFETY: each CPU initialises its own block, once, before its first user entry; no
    // other reference to it exists.
    let block = unsafe { &mut *block };
    (block.this, block.stack_top) = (block as *mut CpuEntry as u64, stack_top);
    (block.number, block.tss) = (cpu as u64, tss as u64);
    // SAFETY: the kernel uses GS for nothing but this block.
    unsafe { x86_64::registers::model_specific::Msr::new(IA32_GS_BASE).write(block.this) };
}

/// This CPU's entry block.
fn this_block() -> *mut CpuEntry {
    let block: u64;
    // SAFETY: in kernel mode GS's base is this CPU's block (`init_cpu`), whose first word
    // is its address.
    unsafe {
        core::arch::asm!("mov {}, gs:[0]", out(reg) block, options(nostack, preserves_flags, readonly))
    };
    block as *mut CpuEntry
}

/// The number of the CPU this runs on (0: the boot CPU).
pub fn this_cpu() -> usize {
    // SAFETY: this CPU's block, set up before its first kernel entry; `number` never
    // changes after.
    unsafe { (*this_block()).number as usize }
}

/// Makes `context` (a thread's, in the kernel's thread table, which never moves) the frame
/// the next user entry on this CPU saves into and the next exit restores; the CPU puts an
/// interrupt's frame just past it (its TSS's ring-0 stack).
fn activate_frame(context: *mut TrapFrame) {
    let at = context as u64;
    // SAFETY: only this CPU, with interrupts off, and its stubs use its block.
    let block = unsafe { &mut *this_block() };
    block.active_frame = at;
    let tss = block.tss as *mut TssBlock;
    let top = x86_64::VirtAddr::new_truncate(at + FRAME_SIZE as u64);
    // SAFETY: this CPU's TSS, which the CPU reads only on entries from ring 3, never while
    // the kernel runs.
    unsafe { (*tss).tss.privilege_stack_table[0] = top };
}

/// The CPUs waiting for the kernel's lock.
static WAITING: AtomicU64 = AtomicU64::new(0);

/// The kernel's lock, held by this CPU. Letting go of it while another CPU waits, the CPU
/// pauses once (`pause`): nothing on hardware, but under QEMU's deterministic time the
/// CPUs run in turns, a `pause` ends a turn, and an interrupt does not; without it the
/// waiting CPU would get the lock only when this one's turn ends, milliseconds later.
struct Locked(Option<MutexGuard<'static, Kernel>>);

impl core::ops::Deref for Locked {
    type Target = Kernel;
    fn deref(&self) -> &Kernel {
        self.0.as_ref().expect("held until dropped")
    }
}

impl core::ops::DerefMut for Locked {
    fn deref_mut(&mut self) -> &mut Kernel {
        self.0.as_mut().expect("held until dropped")
    }
}

impl Drop for Locked {
    fn drop(&mut self) {
        self.0 = None;
        if WAITING.load(Ordering::Acquire) != 0 {
            core::hint::spin_loop();
        }
    }
}

/// Takes the kernel's lock for this CPU, answering address-space requests while it waits
/// (the holder may be waiting for this CPU's answer).
fn lock_kernel() -> Locked {
    let me = this_cpu();
    let mut k = loop {
        if let Some(k) = KERNEL.try_lock() {
            break k;
        }
        WAITING.fetch_or(1 << me, Ordering::AcqRel);
        super::smp::serve_space_request();
        core::hint::spin_loop();
    };
    WAITING.fetch_and(!(1 << me), Ordering::AcqRel);
    k.cpu = me;
    k.core_mut().kicked = false;
    Locked(Some(k))
}

#[unsafe(naked)]
pub(super) unsafe extern "sysv64" fn syscall_entry() {
    naked_asm!(
        "swapgs",
        "mov gs:[{user_rsp}], rsp",
        "mov rsp, gs:[{active}]",
        "add rsp, {frame}",
        // The same layout an interrupt from ring 3 leaves (see TrapFrame).
        "push {user_ss}",
        "push qword ptr gs:[{user_rsp}]",
        "push r11",
        "push {user_cs}",
        "push rcx",
        "push 0",
        "push {vector}",
        "push rax", "push rbx", "push rcx", "push rdx", "push rsi", "push rdi", "push rbp",
        "push r8", "push r9", "push r10", "push r11", "push r12", "push r13", "push r14", "push r15",
        "cld",
        "mov rsp, gs:[{stack}]",
        "call {handler}",
        "mov rsp, gs:[{active}]",
        "pop r15", "pop r14", "pop r13", "pop r12", "pop r11", "pop r10", "pop r9", "pop r8",
        "pop rbp", "pop rdi", "pop rsi", "pop rdx", "pop rcx", "pop rbx", "pop rax",
        "add rsp, 16",
        // sysret restores rip from rcx and rflags from r11: only if they match the frame.
        "cmp rcx, [rsp]",
        "jne 2f",
        "cmp r11, [rsp + 16]",
        "jne 2f",
        "mov rsp, [rsp + 24]",
        "swapgs",
        "sysretq",
        "2:",
        "swapgs",
        "iretq",
        user_rsp = const core::mem::offset_of!(CpuEntry, user_rsp),
        active = const core::mem::offset_of!(CpuEntry, active_frame),
        frame = const FRAME_SIZE,
        stack = const core::mem::offset_of!(CpuEntry, stack_top),
        user_ss = const crate::state::USER_SS,
        user_cs = const crate::state::USER_CS,
        vector = const abi::ipc::VECTOR_SYSCALL,
        handler = sym on_syscall,
    )
}

extern "sysv64" fn on_syscall() {
    let mut k = lock_kernel();
    k.account(super::cpu::rdtsc());
    let current = k.core().current;
    let Some(t) = current.filter(|&t| k.threads[t].is_runnable()) else {
        // Killed or suspended from another CPU while this one waited for the lock: the
        // call is not made now; a suspended thread makes it when it resumes.
        if let Some(t) = current.filter(|&t| !k.threads[t].is_free()) {
            k.threads[t].restart_syscall();
        }
        return finish(k, Outcome::Continue);
    };
    let outcome = crate::syscall::on_syscall(&mut k, t, time::since_boot_ns);
    finish(k, outcome);
}

/// A CPU exception in ring 3 (its frame saved in the thread's context).
pub fn on_user_exception(vector: u64, error_code: u64) {
    let cr2 = x86_64::registers::control::Cr2::read_raw();
    let mut k = lock_kernel();
    k.account(super::cpu::rdtsc());
    // Killed from another CPU meanwhile: nothing to report.
    let Some(t) = k.core().current.filter(|&t| !k.threads[t].is_free()) else {
        return finish(k, Outcome::Continue);
    };
    let outcome = fault::on_exception(&mut k, t, vector, error_code, cr2);
    finish(k, outcome);
}

/// The timer interrupt: time out waits; from ring 3 this may switch threads.
pub fn on_timer(from_user: bool) {
    on_interrupt(from_user, |k| k.on_timer(time::since_boot_ns()));
}

/// User interrupt line `line` fired (already masked in the IOAPIC).
pub fn on_line_interrupt(line: usize, from_user: bool) {
    on_interrupt(from_user, |k| k.irq_fired(line));
}

/// Another CPU changed this one's state, or saw its window boundary pass: it catches up
/// with its schedule, chooses again and programs its timer.
pub fn on_reschedule(from_user: bool) {
    on_interrupt(from_user, |k| k.on_timer(time::since_boot_ns()));
}

/// An interrupt: lets `event` update the kernel (an interrupted thread's registers are
/// already in its context), then returns to a thread chosen again (from ring 0: to the idle
/// loop in `finish`, which chooses).
fn on_interrupt(from_user: bool, event: impl FnOnce(&mut Kernel)) {
    if !RUNNING.load(Ordering::Relaxed) {
        return;
    }
    let mut k = lock_kernel();
    k.account(super::cpu::rdtsc());
    event(&mut k);
    if from_user {
        finish(k, Outcome::Continue);
    } else {
        program_timer(&mut k);
        kick_others(&mut k);
    }
}

fn program_timer(k: &mut Kernel) {
    if k.core().timer_dirty {
        k.core_mut().timer_dirty = false;
        super::lapic::one_shot_at(k.next_event(time::since_boot_ns()));
    }
}

/// Interrupts the other CPUs whose state this entry changed, then pauses once so that
/// under QEMU's deterministic time they get their turn now (see [`Locked`]).
fn kick_others(k: &mut Kernel) {
    let mut kick = k.cpus_to_kick();
    if kick == 0 {
        return;
    }
    while kick != 0 {
        super::smp::send_reschedule(kick.trailing_zeros() as usize);
        kick &= kick - 1;
    }
    core::hint::spin_loop();
}

/// Opens and closes IOAPIC lines until they match what the kernel state wants.
fn apply_line_masks(k: &mut Kernel) {
    let changed = k.irqs.unmasked ^ k.irqs.applied;
    if changed != 0 {
        for line in 0..crate::irq::LINES {
            if changed & (1 << line) != 0 {
                super::ioapic::set_line_masked(line, k.irqs.unmasked & (1 << line) == 0);
            }
        }
        k.irqs.applied = k.irqs.unmasked;
    }
}

/// Picks the next thread (unless the outcome names it) and makes its frame the one the
/// exit restores, halting until one is ready.
fn finish(mut k: Locked, outcome: Outcome) {
    let mut chosen = match outcome {
        Outcome::Halt { success } => qemu::exit(if success {
            qemu::ExitCode::Success
        } else {
            qemu::ExitCode::Failure
        }),
        Outcome::SwitchTo(next) => {
            program_timer(&mut k);
            Some(next)
        }
        Outcome::Continue => {
            apply_line_masks(&mut k);
            None
        }
    };
    loop {
        if chosen.is_none() {
            // What the log holds goes out as far as the UART takes it without waiting.
            crate::log::drain();
            k.catch_up(time::since_boot_ns());
            program_timer(&mut k);
            chosen = k.choose();
        }
        if let Some(next) = chosen {
            switch_to(&mut k, next);
            let partition = k.threads[next].time_partition();
            let core = k.core_mut();
            (core.running, core.running_partition) = (Some(next), Some(partition));
            kick_others(&mut k);
            return;
        }
        let core = k.core_mut();
        (core.running, core.running_partition) = (None, None);
        // An idle CPU holds no thread's state: the thread may move to another CPU (or, if
        // another CPU killed it while this one ran it, its slot may be reused).
        if let Some(previous) = core.current.take() {
            super::fpu::save(k.threads[previous].fpu_save_area());
        }
        kick_others(&mut k);
        #[cfg(feature = "test-hooks")]
        if k.cpu == 0 && k.next_event(0) == crate::thread::NEVER {
            crate::test_hooks::on_idle();
        }
        drop(k);
        // Enable interrupts and halt atomically (sti; hlt), so no wake-up is missed.
        x86_64::instructions::interrupts::enable_and_hlt();
        x86_64::instructions::interrupts::disable();
        k = lock_kernel();
        k.account(super::cpu::rdtsc());
    }
}

fn switch_to(k: &mut Kernel, next: ThreadIdx) {
    let current = k.core().current;
    if current != Some(next) || k.core().reload_bases {
        if current != Some(next) {
            if let Some(previous) = current {
                super::fpu::save(k.threads[previous].fpu_save_area());
            }
            super::fpu::restore(k.threads[next].fpu());
            let space = k.tasks[k.threads[next].task()].space();
            if !space.is_active() {
                space.activate();
                super::smp::set_loaded_space(k.cpu, space.root());
            }
            k.core_mut().current = Some(next);
        }
        load_io_permissions(k, k.threads[next].task());
        let (fs, gs) = k.threads[next].bases();
        super::fpu::set_bases(fs, gs);
        k.core_mut().reload_bases = false;
    }
    activate_frame(k.threads[next].context_ptr());
}

/// Puts `task`'s I/O bitmap into this CPU's TSS, copying 8 KiB only if another task's is
/// there.
fn load_io_permissions(k: &mut Kernel, task: TaskIdx) {
    let id = k.task_id(task);
    if k.core().io_loaded == id {
        return;
    }
    // SAFETY: this CPU's block, set up before its first kernel entry.
    let tss = unsafe { (*this_block()).tss } as *mut TssBlock;
    let [lo, hi] = k.tasks[task].io_bitmap();
    if lo == 0 {
        if k.core().io_loaded != abi::syscall::TaskId::OWN {
            // SAFETY: this CPU's TSS block, not borrowed elsewhere.
            unsafe { super::gdt::load_io_bitmap(tss, None) };
            k.core_mut().io_loaded = abi::syscall::TaskId::OWN;
        }
        return;
    }
    // SAFETY: the task's bitmap frames, direct-mapped, 4 KiB each, not written meanwhile.
    let half = |frame: u64| unsafe {
        core::slice::from_raw_parts(crate::mem::phys_to_virt(frame) as *const u8, 4096)
    };
    // SAFETY: this CPU's TSS block, not borrowed elsewhere.
    unsafe { super::gdt::load_io_bitmap(tss, Some([half(lo), half(hi)])) };
    k.core_mut().io_loaded = id;
}

/// Leaves the boot path (of the boot CPU, which runs the root task first, or of an
/// application processor once the boot CPU did) for user mode: runs this CPU's first
/// ready thread, halting until there is one.
pub fn enter_user_mode() -> ! {
    if this_cpu() == 0 {
        RUNNING.store(true, Ordering::Release);
    }
    while !RUNNING.load(Ordering::Acquire) {
        core::hint::spin_loop();
    }
    let mut k = lock_kernel();
    k.core_mut().last_account = super::cpu::rdtsc();
    finish(k, Outcome::Continue);
    // SAFETY: the active frame is a complete user context (chosen by `finish`); the boot
    // stack is abandoned for good.
    unsafe { restore_frame() }
}

#[unsafe(naked)]
unsafe extern "sysv64" fn restore_frame() -> ! {
    naked_asm!(
        "mov rsp, gs:[{active}]",
        "pop r15",
        "pop r14",
        "pop r13",
        "pop r12",
        "pop r11",
        "pop r10",
        "pop r9",
        "pop r8",
        "pop rbp",
        "pop rdi",
        "pop rsi",
        "pop rdx",
        "pop rcx",
        "pop rbx",
        "pop rax",
        "add rsp, 16",
        "swapgs",
        "iretq",
        active = const core::mem::offset_of!(CpuEntry, active_frame),
    )
}
