//! The ARINC 653 partition runtime of Warden: what a partition program links to use the
//! APEX services through the traits of the [`a653rs`] crate.
//!
//! A partition program names [`Warden`] as a653rs's hypervisor type, implements
//! `a653rs::prelude::Partition<Warden>` and starts with [`partition_entry!`]:
//!
//! ```ignore
//! #![no_std]
//! #![no_main]
//! use a653rs::prelude::*;
//! use apex::Warden;
//!
//! struct Demo;
//! impl Partition<Warden> for Demo {
//!     fn cold_start(&self, ctx: &mut StartContext<Warden>) { /* create processes, ports */ }
//!     fn warm_start(&self, ctx: &mut StartContext<Warden>) { self.cold_start(ctx) }
//! }
//! fn main() { Demo.run() }
//! apex::partition_entry!(main);
//! ```
//!
//! The runtime ([`runtime`]) takes the start record syssw passes to the first thread, runs
//! initialisation on that thread, and maps APEX processes onto threads of the partition's
//! own task (fixed table, stacks from a static arena, static IPC buffers). Partition modes, ports and error
//! reports go to syssw through the request protocol of `user_rt::service`; time comes from
//! the kernel clock; deadlines are watched by one thread at the task's MCP. A bounded heap
//! (a static arena of the program, [`runtime::HEAP_SIZE`] bytes unless [`partition_entry!`]
//! names another size) serves `alloc`.
//!
//! What it must never do: fake success (a service it cannot provide answers with the ARINC
//! code that says so), block while holding its lock, allocate outside its fixed arena, or
//! trust a reply length from syssw beyond the caller's buffer. It is policy-free towards
//! the rest of the system: everything it may do is what the partition's task may do
//! anyway, and syssw checks every request.
//!
//! The pure logic ([`table`], [`time`], [`codes`]) builds without the `runtime` feature and
//! is unit-tested on the host.
#![no_std]

pub mod codes;
pub mod intra;
pub mod table;
pub mod time;

#[cfg(feature = "runtime")]
pub mod heap;
#[cfg(feature = "runtime")]
pub mod main_process;
#[cfg(feature = "runtime")]
pub mod runtime;
#[cfg(feature = "runtime")]
mod warden;

pub use a653rs;
#[cfg(feature = "runtime")]
pub use warden::Warden;

#[cfg(feature = "runtime")]
pub use user_rt;

#[cfg(feature = "runtime")]
#[global_allocator]
static HEAP: heap::BoundedHeap = heap::BoundedHeap;

/// Defines the partition program's ELF entry `_start(start_record)`: sets up the runtime
/// (IPC buffer, syssw's server, process table, heap), then calls `$main` (a `fn()`, which
/// usually runs `Partition::run`) on the initialisation thread. The thread ends when the
/// partition enters NORMAL mode, or when `$main` returns. The heap is a static arena of
/// [`runtime::HEAP_SIZE`] bytes, or of `heap = BYTES` (`partition_entry!(main, heap = 1 << 20)`)
/// for a program that allocates more. The processes' stacks come from a static arena of
/// [`table::STACK_ARENA_SIZE`] bytes, or of `stacks = BYTES`
/// (`partition_entry!(main, heap = 1 << 20, stacks = 1 << 20)`) for a program whose
/// processes' stacks add up to more: each process gets the stack size it asks at creation,
/// at least [`table::MIN_STACK`].
#[cfg(feature = "runtime")]
#[macro_export]
macro_rules! partition_entry {
    ($main:path) => {
        $crate::partition_entry!($main, heap = $crate::runtime::HEAP_SIZE);
    };
    ($main:path, heap = $size:expr) => {
        $crate::partition_entry!(
            $main,
            heap = $size,
            stacks = $crate::table::STACK_ARENA_SIZE
        );
    };
    ($main:path, heap = $size:expr, stacks = $stacks:expr) => {
        // SAFETY: `_start` is the ELF entry symbol; no C start files define it.
        #[allow(unsafe_code)]
        #[unsafe(no_mangle)]
        pub extern "C" fn _start(start_record: u64) -> ! {
            const SIZE: usize = $size;
            const STACKS: usize = $stacks;
            static mut ARENA: $crate::runtime::Arena<SIZE> = $crate::runtime::Arena([0; SIZE]);
            static mut STACK_ARENA: $crate::runtime::Arena<STACKS> =
                $crate::runtime::Arena([0; STACKS]);
            // SAFETY: `ARENA` and `STACK_ARENA` are this function's own statics, used by
            // nothing but the heap and the processes' stacks.
            unsafe {
                $crate::runtime::start(start_record, $main, &raw mut ARENA, &raw mut STACK_ARENA)
            }
        }
    };
}
