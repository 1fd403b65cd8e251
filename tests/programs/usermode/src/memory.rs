//! Mode `memory`: `map`, `map_physical`, `unmap`, `protect` — success paths (data visible
//! through several mappings, in the root and in a child), argument errors, rights (never
//! more than the source, `protect` only removes), all-or-nothing failures, control rights,
//! and a child's write to a page made read-only arriving at its handler as a page fault.

use crate::check::{expect, expect_eq, expect_err, expect_ok, must, status};
use crate::child::{BASIC, BOGUS_ID, CHILD_MCP, LOW, Lab, MS, WAIT, peek, poke, worker};
use root_task::root_info;
use user_rt::abi::ipc::{LABEL_EXCEPTION, MessageTag, REPLY_KILL};
use user_rt::abi::root::RootInfo;
use user_rt::abi::syscall::{
    Abilities, Error, MAP_MAX_PAGES, PageRights, ROOT_INFO_BASE, TaskId, ThreadAttribute, USER_END,
};
use user_rt::println;
use user_rt::sys::{self, Message};

const PAGE: u64 = 4096;
const KERNEL_ADDRESS: u64 = 0xffff_ffff_8000_0000;
const RO: PageRights = PageRights::empty();
const RW: PageRights = PageRights::WRITE;

pub fn run() {
    let mut lab = Lab::new();
    mapping(&mut lab);
    arguments(&mut lab);
    physical(&mut lab);
    rights(&mut lab);
    control(&mut lab);
    child_fault(&mut lab);
    println!("all memory checks passed");
    let _ = sys::system_halt(true);
}

fn read(address: u64) -> u64 {
    // SAFETY: only called for pages this mode mapped readable in the root and keeps mapped.
    unsafe { peek(address) }
}

fn write(address: u64, value: u64) {
    // SAFETY: only called for pages this mode mapped writable in the root; no Rust
    // references to them exist.
    unsafe { poke(address, value) }
}

fn mapping(lab: &mut Lab) {
    let frame = lab.frames(2);
    let va = lab.address(2);
    expect_ok(
        "map_physical of two frames of RootInfo memory",
        sys::map_physical(None, frame, va, 2, RW),
    );
    write(va, 0x1111);
    write(va + PAGE + 8, 0x2222);
    expect_eq(
        "data written to a new mapping reads back",
        (read(va), read(va + PAGE + 8)),
        (0x1111, 0x2222),
    );
    let va2 = lab.address(2);
    expect_ok(
        "map of the caller's pages to a second address",
        sys::map(None, va, va2, 2, RW),
    );
    expect_eq(
        "data written through one mapping is visible through the second",
        (read(va2), read(va2 + PAGE + 8)),
        (0x1111, 0x2222),
    );
    write(va2, 0x3333);
    expect_eq(
        "data written through the second mapping is visible through the first",
        read(va),
        0x3333,
    );
    let va3 = lab.address(1);
    expect_ok(
        "map_physical of a frame that is already mapped elsewhere",
        sys::map_physical(None, frame, va3, 1, RO),
    );
    expect_eq(
        "a frame mapped twice shows the same data",
        read(va3),
        0x3333,
    );

    expect_err(
        "map_physical onto a mapped page is AlreadyMapped",
        sys::map_physical(None, frame, va, 1, RW),
        Error::AlreadyMapped,
    );
    let va4 = lab.address(2);
    must(
        "map_physical",
        sys::map_physical(None, frame, va4 + PAGE, 1, RO),
    );
    expect_err(
        "map onto a range whose second page is mapped is AlreadyMapped",
        sys::map(None, va, va4, 2, RO),
        Error::AlreadyMapped,
    );
    expect(
        "a map that fails maps nothing (its first page stays unmapped)",
        !lab.is_mapped(va4),
    );
    let unmapped = lab.address(1);
    let dst = lab.address(2);
    expect_err(
        "map from an unmapped source page is BadAddress",
        sys::map(None, unmapped, dst, 1, RO),
        Error::BadAddress,
    );
    // va + PAGE is mapped, the guard page after it is not.
    expect_err(
        "map from a partly unmapped source range is BadAddress",
        sys::map(None, va + PAGE, dst, 2, RO),
        Error::BadAddress,
    );
    expect(
        "a map that fails on its last source page maps nothing",
        !lab.is_mapped(dst),
    );

    expect_ok("unmap of the second mapping", sys::unmap(None, va2, 2));
    expect(
        "unmapped pages are gone",
        !lab.is_mapped(va2) && !lab.is_mapped(va2 + PAGE),
    );
    expect_eq(
        "the first mapping keeps its data after the second is unmapped",
        read(va),
        0x3333,
    );
    expect_ok(
        "unmap of pages that are not mapped succeeds",
        sys::unmap(None, va2, 2),
    );
}

fn arguments(lab: &mut Lab) {
    let va = lab.shared(None, 1);
    let dst = lab.address(1);
    let frame = lab.frames(1);
    let bogus = Some(TaskId(BOGUS_ID));
    let invalid = [
        (
            "map with an unaligned source is InvalidArgument",
            sys::map(None, va + 8, dst, 1, RO),
        ),
        (
            "map with an unaligned destination is InvalidArgument",
            sys::map(None, va, dst + 8, 1, RO),
        ),
        (
            "map_physical of an unaligned frame is InvalidArgument",
            sys::map_physical(None, frame + 8, dst, 1, RO),
        ),
        (
            "map of zero pages is InvalidArgument",
            sys::map(None, va, dst, 0, RO),
        ),
        (
            "map_physical of zero pages is InvalidArgument",
            sys::map_physical(None, frame, dst, 0, RO),
        ),
        (
            "map of more than MAP_MAX_PAGES pages is InvalidArgument",
            sys::map(None, va, dst, MAP_MAX_PAGES + 1, RO),
        ),
        (
            "map_physical of more than MAP_MAX_PAGES pages is InvalidArgument",
            sys::map_physical(None, frame, dst, MAP_MAX_PAGES + 1, RO),
        ),
        (
            "map to a kernel address is InvalidArgument",
            sys::map(None, va, KERNEL_ADDRESS, 1, RO),
        ),
        (
            "map_physical to a kernel address is InvalidArgument",
            sys::map_physical(None, frame, KERNEL_ADDRESS, 1, RO),
        ),
        (
            "map to page 0 is InvalidArgument",
            sys::map(None, va, 0, 1, RO),
        ),
        (
            "map_physical to a range crossing the end of user space is InvalidArgument",
            sys::map_physical(None, frame, USER_END - PAGE, 2, RO),
        ),
        (
            "unmap of an unaligned address is InvalidArgument",
            sys::unmap(None, va + 8, 1),
        ),
        (
            "unmap of zero pages is InvalidArgument",
            sys::unmap(None, va, 0),
        ),
        (
            "unmap of more than MAP_MAX_PAGES pages is InvalidArgument",
            sys::unmap(None, va, MAP_MAX_PAGES + 1),
        ),
        (
            "protect of an unaligned address is InvalidArgument",
            sys::protect(None, va + 8, 1, RO),
        ),
        (
            "protect of zero pages is InvalidArgument",
            sys::protect(None, va, 0, RO),
        ),
        (
            "protect of more than MAP_MAX_PAGES pages is InvalidArgument",
            sys::protect(None, va, MAP_MAX_PAGES + 1, RO),
        ),
    ];
    for (what, result) in invalid {
        expect_err(what, result, Error::InvalidArgument);
    }
    let missing = [
        (
            "map into a nonexistent task is NoSuchObject",
            sys::map(bogus, va, dst, 1, RO),
        ),
        (
            "map_physical into a nonexistent task is NoSuchObject",
            sys::map_physical(bogus, frame, dst, 1, RO),
        ),
        (
            "unmap in a nonexistent task is NoSuchObject",
            sys::unmap(bogus, dst, 1),
        ),
        (
            "protect in a nonexistent task is NoSuchObject",
            sys::protect(bogus, dst, 1, RO),
        ),
    ];
    for (what, result) in missing {
        expect_err(what, result, Error::NoSuchObject);
    }
    expect(
        "failed calls left the destination unmapped",
        !lab.is_mapped(dst),
    );

    // Exactly MAP_MAX_PAGES works.
    let big = lab.frames(MAP_MAX_PAGES);
    let at = lab.address(MAP_MAX_PAGES);
    expect_ok(
        "map_physical of exactly MAP_MAX_PAGES pages",
        sys::map_physical(None, big, at, MAP_MAX_PAGES, RW),
    );
    let last = at + (MAP_MAX_PAGES - 1) * PAGE;
    write(last, 0x4444);
    expect_eq(
        "the last page of a maximal mapping works",
        read(last),
        0x4444,
    );
    expect_ok(
        "protect of exactly MAP_MAX_PAGES pages",
        sys::protect(None, at, MAP_MAX_PAGES, RO),
    );
    expect_ok(
        "unmap of exactly MAP_MAX_PAGES pages",
        sys::unmap(None, at, MAP_MAX_PAGES),
    );
    expect(
        "all pages of a maximal unmap are gone",
        !lab.is_mapped(at) && !lab.is_mapped(last),
    );
}

/// A page-aligned physical address outside every RootInfo region.
fn outside_frame(info: &RootInfo) -> u64 {
    let highest = info
        .regions()
        .iter()
        .map(|r| r.start + r.pages * PAGE)
        .max()
        .unwrap_or(0);
    [0, 0xa_0000, 0xfee0_0000, highest, highest + (1 << 30)]
        .into_iter()
        .find(|&f| !info.contains(f, 1))
        .expect("some frame outside RootInfo memory")
}

fn physical(lab: &mut Lab) {
    let info = root_info();
    let dst = lab.address(2);
    let outside = outside_frame(info);
    println!("memory: frame {outside:#x} is outside RootInfo memory");
    expect_err(
        "map_physical of a frame outside RootInfo memory is BadAddress",
        sys::map_physical(None, outside, dst, 1, RO),
        Error::BadAddress,
    );
    // The last frame of a region whose end is not RootInfo memory, plus the next one.
    let edge = info
        .regions()
        .iter()
        .map(|r| r.start + r.pages * PAGE)
        .find(|&end| !info.contains(end, 1));
    if let Some(end) = edge {
        expect_err(
            "map_physical of a range leaving RootInfo memory is BadAddress",
            sys::map_physical(None, end - PAGE, dst, 2, RO),
            Error::BadAddress,
        );
    }
    expect(
        "failed map_physical calls mapped nothing",
        !lab.is_mapped(dst),
    );
}

fn rights(lab: &mut Lab) {
    let dst = lab.address(1);
    expect_err(
        "map with WRITE from a read-only page (RootInfo) is BadAddress",
        sys::map(None, ROOT_INFO_BASE, dst, 1, RW),
        Error::BadAddress,
    );
    let page = lab.shared(None, 2);
    write(page, 77);
    expect_err(
        "map with EXECUTE from a non-executable page is BadAddress",
        sys::map(None, page, dst, 1, PageRights::EXECUTE),
        Error::BadAddress,
    );
    expect_ok(
        "map with fewer rights than the source",
        sys::map(None, page, dst, 1, RO),
    );
    let dst2 = lab.address(1);
    expect_err(
        "map with WRITE from a read-only mapping of writable memory is BadAddress",
        sys::map(None, dst, dst2, 1, RW),
        Error::BadAddress,
    );
    expect_eq("a read-only mapping reads the data", read(dst), 77);

    expect_ok(
        "protect of a writable page to read-only",
        sys::protect(None, page, 1, RO),
    );
    expect_err(
        "a page protected read-only cannot be mapped writable any more",
        sys::map(None, page, dst2, 1, RW),
        Error::BadAddress,
    );
    expect_eq("a page protected read-only still reads", read(page), 77);
    let again = sys::protect(None, page, 1, RW);
    println!("memory: protect asking for more rights returned {again:?}");
    // The ABI leaves open whether asking for more rights is an error (this kernel: the
    // page lacks them, BadAddress) or a no-op; what matters is that nothing is added.
    expect(
        "protect cannot add rights (the page stays read-only)",
        matches!(
            again,
            Ok(()) | Err(Error::BadAddress) | Err(Error::InvalidArgument)
        ) && sys::map(None, page, dst2, 1, RW) == Err(Error::BadAddress),
    );
    let unmapped = lab.address(1);
    expect_err(
        "protect of an unmapped page is BadAddress",
        sys::protect(None, unmapped, 1, RO),
        Error::BadAddress,
    );
    // page + PAGE is writable, the guard page after it unmapped.
    expect_err(
        "protect of a range with an unmapped page is BadAddress",
        sys::protect(None, page + PAGE, 2, RO),
        Error::BadAddress,
    );
    expect_ok(
        "a protect that fails changes nothing (the page stays writable)",
        sys::map(None, page + PAGE, dst2, 1, RW),
    );
}

const M_MAP: usize = 0;
const M_MAP_PHYSICAL: usize = 1;
const M_MAP_INTO_ROOT: usize = 2;
const M_UNMAP_IN_ROOT: usize = 3;
const M_PROTECT_IN_ROOT: usize = 4;

worker!(
    /// Tries to map its own block page to arg 1 and frame arg 2 to arg 3, then to operate
    /// on page arg 4 of the root task (arg 0).
    fn map_probe(b, ipc) {
        let own = b.arg(5);
        let root = Some(TaskId(b.arg(0)));
        b.set_code(M_MAP, &sys::map(None, own, b.arg(1), 1, RO));
        b.set_code(
            M_MAP_PHYSICAL,
            &sys::map_physical(None, b.arg(2), b.arg(3), 1, RO),
        );
        b.set_code(
            M_MAP_INTO_ROOT,
            &sys::map(root, own, b.arg(1) + 2 * PAGE, 1, RO),
        );
        b.set_code(M_UNMAP_IN_ROOT, &sys::unmap(root, b.arg(4), 1));
        b.set_code(M_PROTECT_IN_ROOT, &sys::protect(root, b.arg(4), 1, RO));
    }
);

fn probe(lab: &mut Lab, name: &str, abilities: Abilities) -> crate::child::Worker {
    let task = lab.task(name, abilities, CHILD_MCP);
    let frame = lab.frames(1);
    let dst = lab.address(4);
    let victim = lab.shared(None, 1);
    let w = lab.worker(
        Some(task),
        map_probe,
        LOW,
        &[lab.task.0, dst, frame, dst + PAGE, victim],
    );
    // Arg 5: the block itself, a page mapped in the child.
    w.block.set_arg(5, w.block.address());
    w.start();
    w.wait_done("map probe");
    must("task_kill", sys::task_kill(task));
    w
}

fn control(lab: &mut Lab) {
    let w = probe(lab, "m-nomap", BASIC);
    let r = |i| status(w.block.result(i));
    expect_err(
        "map without the MAP ability is AbilityDenied",
        r(M_MAP),
        Error::AbilityDenied,
    );
    expect_err(
        "map_physical without the PHYSICAL_MEMORY ability is AbilityDenied",
        r(M_MAP_PHYSICAL),
        Error::AbilityDenied,
    );
    let w = probe(lab, "m-map", BASIC | Abilities::MAP);
    let r = |i| status(w.block.result(i));
    expect_eq(
        "a child with MAP maps within its own task",
        r(M_MAP),
        Ok(()),
    );
    expect_err(
        "map into an ancestor task is NotPermitted",
        r(M_MAP_INTO_ROOT),
        Error::NotPermitted,
    );
    expect_err(
        "unmap in an ancestor task is NotPermitted",
        r(M_UNMAP_IN_ROOT),
        Error::NotPermitted,
    );
    expect_err(
        "protect in an ancestor task is NotPermitted",
        r(M_PROTECT_IN_ROOT),
        Error::NotPermitted,
    );
}

worker!(
    /// Reads and writes the shared page arg 0, then (after notification bit 0) writes it
    /// again, which faults once the root made it read-only.
    fn writer(b, ipc) {
        let page = b.arg(0);
        // SAFETY: arg 0 is a page the root mapped writable into this task (and keeps
        // mapped); it may become read-only, which only makes the write fault.
        b.set_result(0, unsafe { peek(page) });
        // SAFETY: as for the read.
        unsafe { poke(page, 0xabcd) };
        b.set_step(1);
        b.set_code(1, &sys::notify_wait(1, WAIT));
        b.set_step(2);
        // SAFETY: as above; this write is meant to fault.
        unsafe { poke(page, 0xdead) };
        b.set_step(3);
    }
);

fn child_fault(lab: &mut Lab) {
    let task = lab.task("m-writer", BASIC, CHILD_MCP);
    let page = lab.shared(Some(task), 1);
    write(page, 0x5151);
    let w = lab.worker(Some(task), writer, LOW, &[page]);
    must(
        "thread_set ExceptionHandler",
        sys::thread_set(Some(w.id), ThreadAttribute::ExceptionHandler, lab.me.0),
    );
    w.start();
    w.wait_step(1, "writer reaches step 1");
    expect_eq(
        "a child reads what the root wrote to a shared page",
        w.block.result(0),
        0x5151,
    );
    expect_eq(
        "the root reads what the child wrote to a shared page",
        read(page),
        0xabcd,
    );
    expect_ok(
        "protect of a child's page to read-only",
        sys::protect(Some(task), page, 1, RO),
    );
    must("notify_signal", sys::notify_signal(w.id, 1));
    let m = expect_ok(
        "the child's write to the read-only page reaches its handler",
        sys::receive(Some(w.id), WAIT),
    );
    let ex = lab.ipc.exception();
    // Error code: present (bit 0), write (bit 1), user (bit 2).
    expect_eq(
        "it is a page fault on that page: user write to a present page",
        (
            m.message.tag.label(),
            ex.vector,
            ex.fault_address,
            ex.error_code & 7,
        ),
        (LABEL_EXCEPTION, 14, page, 7),
    );
    expect_ok(
        "reply REPLY_KILL to the page fault",
        sys::reply(
            w.id,
            &Message {
                tag: MessageTag::new(REPLY_KILL, 0, 0),
                words: [0; 3],
            },
        ),
    );
    sys::sleep(5 * MS);
    expect_eq(
        "the faulting write did not happen and the thread did not continue",
        (read(page), w.block.step()),
        (0xabcd, 2),
    );
    expect_err(
        "the thread whose handler replied REPLY_KILL is gone",
        sys::thread_kill(w.id),
        Error::NoSuchObject,
    );
    must("task_kill", sys::task_kill(task));
}
