//! Mode `ipc`: synchronous IPC between the root's threads and threads of child tasks —
//! call/reply and a `reply_wait` server loop, send/receive (open and from one thread), a
//! 4096-byte data copy each way, map and grant items, timeouts (poll, finite, infinite),
//! sender queues ordered by priority, `PeerGone`, `NotWaiting`, IPC-buffer checks,
//! communication rights between sibling tasks (`task_allow_send`) and notifications.

use crate::check::{expect, expect_eq, expect_err, expect_ok, must, status};
use crate::child::{BASIC, BOGUS_ID, LOW, Lab, MS, WAIT, peek, poke, worker};
use root_task::spawn;
use user_rt::abi::ipc::{IPC_DATA_MAX, MAP_ITEM_GRANT, MapItem, MessageTag, ReceiveWindow};
use user_rt::abi::syscall::{
    Abilities, Error, PageRights, ROOT_INFO_BASE, TIMEOUT_INFINITE, TaskId, ThreadAttribute,
    ThreadId,
};
use user_rt::println;
use user_rt::sys::{self, Message, Received};

/// MCP of the peer tasks (room for the priorities of the queueing test).
const PEER_MCP: u8 = 250;
const SERVER_PRIORITY: u8 = 150;

// Server operations (message labels).
const OP_ADD: u32 = 1;
const OP_DATA: u32 = 2;
const OP_READ_WINDOW: u32 = 3;
const OP_WRITE_WINDOW: u32 = 4;

const MAGIC1: u64 = 0x1111_2222_3333_4444;
const MAGIC2: u64 = 0x5555_6666_7777_8888;
const MAGIC3: u64 = 0x9999_aaaa_bbbb_cccc;
const MAGIC4: u64 = 0xdddd_eeee_ffff_0001;

fn pattern(i: usize) -> u8 {
    (i as u8).wrapping_mul(7).wrapping_add(3) ^ (i >> 8) as u8
}

fn reply_pattern(i: usize) -> u8 {
    (i as u8).wrapping_mul(13).wrapping_add(5) ^ 0x5a ^ (i >> 8) as u8
}

fn read(address: u64) -> u64 {
    // SAFETY: only called for pages this mode mapped in the root and keeps mapped.
    unsafe { peek(address) }
}

fn write(address: u64, value: u64) {
    // SAFETY: only called for pages this mode mapped writable in the root; no references.
    unsafe { poke(address, value) }
}

fn msg(label: u32, words: [u64; 3]) -> Message {
    Message::new(label, words)
}

/// Runs `f` and returns its result and how long it took (ns).
fn timed<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let t0 = sys::clock();
    let r = f();
    (r, sys::clock() - t0)
}

pub fn run() {
    let mut lab = Lab::new();
    let peer = lab.task("i-peer", BASIC, PEER_MCP);
    let window = lab.address(1);
    let server = lab.worker(Some(peer), serve, SERVER_PRIORITY, &[window]);
    server.start();
    let s = server.id;

    call_and_data(&mut lab, s);
    map_items(&mut lab, s, peer, window);
    timeouts(&mut lab, peer);
    send_receive(&mut lab, peer);
    priority_queue(&mut lab, peer);
    errors(&mut lab, peer, s);
    rights(&mut lab);
    notifications(&mut lab, peer);
    expect(
        "the server saw no receive error",
        !server.block.is_done() && server.block.result(0) == 0,
    );
    println!("all ipc checks passed");
    let _ = sys::system_halt(true);
}

worker!(
    /// A server in a `reply_wait` loop. Arg 0: its receive window (one page).
    fn serve(b, ipc) {
        let window = b.arg(0);
        ipc.set_window(ReceiveWindow {
            base: window,
            pages: 1,
        });
        let mut next = sys::receive(None, TIMEOUT_INFINITE);
        loop {
            let m: Received = match next {
                Ok(m) => m,
                Err(e) => {
                    b.set_code(0, &Err::<(), _>(e));
                    break;
                }
            };
            b.add_result(1, 1);
            let (tag, w) = (m.message.tag, m.message.words);
            let reply = match tag.label() {
                OP_ADD => msg(OP_ADD, [w[0] + w[1] + w[2], m.sender.0, tag.len() as u64]),
                OP_DATA => {
                    let mut chunk = [0u8; 256];
                    let mut bad = 0u64;
                    for start in (0..IPC_DATA_MAX).step_by(chunk.len()) {
                        ipc.read_data(start, &mut chunk);
                        for (i, x) in chunk.iter().enumerate() {
                            if *x != pattern(start + i) {
                                bad += 1;
                            }
                        }
                        for (i, x) in chunk.iter_mut().enumerate() {
                            *x = reply_pattern(start + i);
                        }
                        ipc.write_data(start, &chunk);
                    }
                    Message {
                        tag: MessageTag::new(OP_DATA, IPC_DATA_MAX, 0),
                        words: [bad, tag.len() as u64, 0],
                    }
                }
                OP_READ_WINDOW => {
                    // SAFETY: the root sends this only once a map item put a page at the
                    // window (readable for this task).
                    let value = unsafe { peek(window) };
                    msg(OP_READ_WINDOW, [value, tag.items() as u64, 0])
                }
                OP_WRITE_WINDOW => {
                    // SAFETY: as above, and the item was writable.
                    unsafe { poke(window, w[0]) };
                    msg(OP_WRITE_WINDOW, [0; 3])
                }
                other => msg(0xbad, [other as u64, 0, 0]),
            };
            next = sys::reply_wait(Some(m.sender), TIMEOUT_INFINITE, &reply);
        }
    }
);

fn call_and_data(lab: &mut Lab, s: ThreadId) {
    let r = expect_ok(
        "call to a server thread in a child task",
        sys::ipc_call(s, WAIT, &msg(OP_ADD, [1, 2, 3])),
    );
    expect_eq(
        "the reply comes from the server with its label and words",
        (r.sender, r.message.tag.label(), r.message.words[0]),
        (s, OP_ADD, 6),
    );
    expect_eq(
        "the server saw the caller as the sender",
        r.message.words[1],
        lab.me.0,
    );
    let r = expect_ok(
        "a second call is served by the reply_wait loop",
        sys::ipc_call(s, WAIT, &msg(OP_ADD, [10, 20, 30])),
    );
    expect_eq("the second reply is right", r.message.words[0], 60);

    let mut chunk = [0u8; 256];
    for start in (0..IPC_DATA_MAX).step_by(chunk.len()) {
        for (i, x) in chunk.iter_mut().enumerate() {
            *x = pattern(start + i);
        }
        lab.ipc.write_data(start, &chunk);
    }
    let r = expect_ok(
        "call with 4096 data bytes",
        sys::ipc_call(
            s,
            WAIT,
            &Message {
                tag: MessageTag::new(OP_DATA, IPC_DATA_MAX, 0),
                words: [0; 3],
            },
        ),
    );
    expect_eq(
        "the server received all 4096 data bytes intact",
        (r.message.words[1], r.message.words[0]),
        (IPC_DATA_MAX as u64, 0),
    );
    let mut bad = 0;
    for start in (0..IPC_DATA_MAX).step_by(chunk.len()) {
        lab.ipc.read_data(start, &mut chunk);
        bad += chunk
            .iter()
            .enumerate()
            .filter(|(i, x)| **x != reply_pattern(start + i))
            .count();
    }
    expect_eq(
        "the reply's 4096 data bytes arrived intact",
        (r.message.tag.len(), bad),
        (IPC_DATA_MAX, 0),
    );
}

fn item_call(s: ThreadId, label: u32, items: usize) -> Result<Received, Error> {
    sys::ipc_call(
        s,
        WAIT,
        &Message {
            tag: MessageTag::new(label, 0, items),
            words: [0; 3],
        },
    )
}

fn map_items(lab: &mut Lab, s: ThreadId, peer: TaskId, window: u64) {
    let rw = PageRights::WRITE.bits() as u32;
    let page = lab.shared(None, 1);
    write(page, MAGIC1);
    lab.ipc.set_item(
        0,
        MapItem {
            source: page,
            pages: 1,
            flags: rw,
        },
    );
    let r = expect_ok("call with a map item", item_call(s, OP_READ_WINDOW, 1));
    expect_eq(
        "a map item shares the page: the receiver reads the sender's data",
        (r.message.words[0], r.message.words[1]),
        (MAGIC1, 1),
    );
    write(page, MAGIC2);
    let r = expect_ok("call", item_call(s, OP_READ_WINDOW, 0));
    expect_eq(
        "the receiver sees the sender's later writes to the shared page",
        r.message.words[0],
        MAGIC2,
    );
    expect_ok(
        "call",
        sys::ipc_call(s, WAIT, &msg(OP_WRITE_WINDOW, [MAGIC3, 0, 0])),
    );
    expect_eq(
        "the sender sees the receiver's writes to the shared page",
        read(page),
        MAGIC3,
    );
    expect_err(
        "a map item into an occupied receive window is AlreadyMapped",
        item_call(s, OP_READ_WINDOW, 1),
        Error::AlreadyMapped,
    );
    let r = expect_ok(
        "the receiver keeps waiting after a failed send",
        sys::ipc_call(s, WAIT, &msg(OP_ADD, [1, 1, 1])),
    );
    expect_eq("and serves the next call", r.message.words[0], 3);
    expect_ok(
        "unmap of a child's receive window by its parent",
        sys::unmap(Some(peer), window, 1),
    );

    lab.ipc.set_item(
        0,
        MapItem {
            source: ROOT_INFO_BASE,
            pages: 1,
            flags: rw,
        },
    );
    expect_err(
        "a map item with more rights than its source is BadAddress",
        item_call(s, OP_READ_WINDOW, 1),
        Error::BadAddress,
    );
    let two = lab.shared(None, 2);
    lab.ipc.set_item(
        0,
        MapItem {
            source: two,
            pages: 2,
            flags: rw,
        },
    );
    let r = item_call(s, OP_READ_WINDOW, 1);
    println!(
        "ipc: a 2-page item into a 1-page window gave {:?}",
        r.map(drop)
    );
    expect(
        "a map item larger than the receive window fails",
        r.is_err(),
    );
    expect_ok(
        "the receiver still serves calls after failed map items",
        sys::ipc_call(s, WAIT, &msg(OP_ADD, [0; 3])),
    );

    let granted = lab.shared(None, 1);
    write(granted, MAGIC4);
    lab.ipc.set_item(
        0,
        MapItem {
            source: granted,
            pages: 1,
            flags: rw | MAP_ITEM_GRANT,
        },
    );
    let r = expect_ok("call with a grant item", item_call(s, OP_READ_WINDOW, 1));
    expect_eq(
        "a grant item moves the page: the receiver reads its data",
        r.message.words[0],
        MAGIC4,
    );
    expect(
        "a grant item unmaps the page from the sender",
        !lab.is_mapped(granted),
    );
    must("unmap of the window", sys::unmap(Some(peer), window, 1));
}

worker!(
    /// Waits for notification bit 0, sleeps 20 ms, then sends label 77 to thread arg 0.
    fn delayed_sender(b, ipc) {
        b.set_code(1, &sys::notify_wait(1, WAIT));
        sys::sleep(20 * MS);
        b.set_code(0, &sys::send(ThreadId(b.arg(0)), WAIT, &msg(77, [0; 3])));
    }
);

fn timeouts(lab: &mut Lab, peer: TaskId) {
    expect_err(
        "receive with timeout 0 and no sender is TimedOut",
        sys::receive(None, 0),
        Error::TimedOut,
    );
    let (r, took) = timed(|| sys::receive(None, 20 * MS));
    println!("ipc: receive with a 20 ms timeout took {} us", took / 1000);
    expect_err(
        "receive with a 20 ms timeout and no sender is TimedOut",
        r,
        Error::TimedOut,
    );
    expect(
        "receive with a 20 ms timeout waited at least 20 ms",
        took >= 20 * MS,
    );

    let d = lab.worker(Some(peer), delayed_sender, LOW, &[lab.me.0]);
    d.start();
    sys::sleep(5 * MS);
    expect_err(
        "send with timeout 0 to a thread that is not receiving is TimedOut",
        sys::send(d.id, 0, &msg(1, [0; 3])),
        Error::TimedOut,
    );
    expect_err(
        "call with timeout 0 to a thread that is not receiving is TimedOut",
        sys::ipc_call(d.id, 0, &msg(1, [0; 3])),
        Error::TimedOut,
    );
    let (r, took) = timed(|| sys::ipc_call(d.id, 20 * MS, &msg(1, [0; 3])));
    println!("ipc: call with a 20 ms timeout took {} us", took / 1000);
    expect_err(
        "call with a 20 ms timeout to a thread that is not receiving is TimedOut",
        r,
        Error::TimedOut,
    );
    expect(
        "call with a 20 ms timeout waited at least 20 ms",
        took >= 20 * MS,
    );
    must("notify_signal", sys::notify_signal(d.id, 1));
    let (r, took) = timed(|| sys::receive(Some(d.id), TIMEOUT_INFINITE));
    let r = expect_ok(
        "receive with an infinite timeout gets a message sent 20 ms later",
        r,
    );
    expect_eq(
        "the delayed message has its label",
        r.message.tag.label(),
        77,
    );
    expect(
        "receive with an infinite timeout waited for the message",
        took >= 20 * MS,
    );
    d.wait_done("delayed sender");
    expect_eq(
        "the delayed sender's send succeeded",
        status(d.block.result(0)),
        Ok(()),
    );
}

worker!(
    /// Receives one message (timeout `WAIT`) and reports it.
    fn receiver(b, ipc) {
        let r = sys::receive(None, WAIT);
        b.set_code(0, &r);
        if let Ok(m) = r {
            b.set_result(1, m.sender.0);
            b.set_result(2, m.message.tag.label() as u64);
            for (i, w) in m.message.words.iter().enumerate() {
                b.set_result(3 + i, *w);
            }
        }
    }
);

worker!(
    /// Sends label arg 1 (and arg 1 as first word) to thread arg 0.
    fn sender(b, ipc) {
        let label = b.arg(1);
        b.set_code(
            0,
            &sys::send(ThreadId(b.arg(0)), WAIT, &msg(label as u32, [label, 0, 0])),
        );
    }
);

worker!(
    /// Like `sender`, but only after notification bit 0.
    fn gated_sender(b, ipc) {
        b.set_code(1, &sys::notify_wait(1, WAIT));
        let label = b.arg(1);
        b.set_code(
            0,
            &sys::send(ThreadId(b.arg(0)), WAIT, &msg(label as u32, [label, 0, 0])),
        );
    }
);

fn send_receive(lab: &mut Lab, peer: TaskId) {
    let r = lab.worker(Some(peer), receiver, LOW, &[]);
    r.start();
    // The receiver has not run yet: the send waits until it receives.
    expect_ok(
        "send to a thread that receives later",
        sys::send(r.id, WAIT, &msg(5, [7, 8, 9])),
    );
    r.wait_done("receiver");
    expect_eq(
        "the receiver got the sender, the label and the words",
        (
            status(r.block.result(0)),
            r.block.result(1),
            r.block.result(2),
            [r.block.result(3), r.block.result(4), r.block.result(5)],
        ),
        (Ok(()), lab.me.0, 5, [7, 8, 9]),
    );

    let a = lab.worker(Some(peer), sender, LOW, &[lab.me.0, 1]);
    let b = lab.worker(Some(peer), sender, LOW, &[lab.me.0, 2]);
    a.start();
    b.start();
    sys::sleep(5 * MS);
    let m = expect_ok(
        "receive from one thread while two senders wait",
        sys::receive(Some(b.id), WAIT),
    );
    expect_eq(
        "receive from one thread takes its message, not the first queued",
        (m.sender, m.message.tag.label(), m.message.words[0]),
        (b.id, 2, 2),
    );
    let m = expect_ok("open receive", sys::receive(None, WAIT));
    expect_eq(
        "the other sender's message is still queued",
        (m.sender, m.message.tag.label()),
        (a.id, 1),
    );
    expect_err(
        "once all senders are served, a poll is TimedOut",
        sys::receive(None, 0),
        Error::TimedOut,
    );
    a.wait_done("sender a");
    b.wait_done("sender b");
    expect_eq(
        "both senders' sends succeeded",
        (status(a.block.result(0)), status(b.block.result(0))),
        (Ok(()), Ok(())),
    );
}

fn priority_queue(lab: &mut Lab, peer: TaskId) {
    // Senders become blocked in this order; labels 1..=5.
    let priorities = [110u8, 115, 120, 115, 130];
    let mut senders = [None; 5];
    for (i, p) in priorities.iter().enumerate() {
        let w = lab.worker(Some(peer), gated_sender, *p, &[lab.me.0, i as u64 + 1]);
        w.start();
        senders[i] = Some(w);
    }
    sys::sleep(5 * MS);
    for w in senders.iter().flatten() {
        must("notify_signal", sys::notify_signal(w.id, 1));
        // Let this one block in its send before waking the next.
        sys::sleep(2 * MS);
    }
    let mut order = [0u32; 5];
    for o in order.iter_mut() {
        *o = must("receive from the queued senders", sys::receive(None, WAIT))
            .message
            .tag
            .label();
    }
    // 130, 120, then the two 115s in arrival order, then 110.
    expect_eq(
        "senders are received highest priority first, FIFO within a priority",
        order,
        [5, 3, 2, 4, 1],
    );
}

worker!(
    /// Receives a call and never replies.
    fn silent(b, ipc) {
        b.set_code(0, &sys::receive(None, WAIT));
        b.set_step(1);
        loop {
            let _ = sys::notify_wait(0, TIMEOUT_INFINITE);
        }
    }
);

worker!(
    /// Calls thread arg 0 (timeout 2 × WAIT) and reports the outcome.
    fn caller(b, ipc) {
        b.set_code(
            0,
            &sys::ipc_call(ThreadId(b.arg(0)), 2 * WAIT, &msg(9, [0; 3])),
        );
    }
);

worker!(
    /// Drops its IPC buffer, then receives twice: a register-only message (needs no
    /// buffer), then a message with data (needs one).
    fn no_buffer(b, ipc) {
        b.set_code(0, &sys::thread_set(None, ThreadAttribute::IpcBuffer, 0));
        b.set_step(1);
        let r = sys::receive(None, WAIT);
        b.set_code(1, &r);
        b.set_result(2, r.map_or(0, |m| m.message.tag.label() as u64));
        b.set_step(2);
        b.set_code(3, &sys::receive(None, WAIT));
    }
);

fn errors(lab: &mut Lab, peer: TaskId, s: ThreadId) {
    let bogus = ThreadId(BOGUS_ID);
    expect_err(
        "send to a nonexistent thread is NoSuchObject",
        sys::send(bogus, 0, &msg(1, [0; 3])),
        Error::NoSuchObject,
    );
    expect_err(
        "call to a nonexistent thread is NoSuchObject",
        sys::ipc_call(bogus, 0, &msg(1, [0; 3])),
        Error::NoSuchObject,
    );
    expect_err(
        "receive from a nonexistent thread is NoSuchObject",
        sys::receive(Some(bogus), 0),
        Error::NoSuchObject,
    );
    expect_err(
        "reply to a thread that is not calling is NotWaiting",
        sys::reply(s, &msg(1, [0; 3])),
        Error::NotWaiting,
    );
    expect_err(
        "reply_wait to a thread that is not calling is NotWaiting",
        sys::reply_wait(Some(s), 0, &msg(1, [0; 3])),
        Error::NotWaiting,
    );

    // PeerGone: the callee dies while the caller waits for its reply.
    let k = lab.worker(Some(peer), silent, LOW, &[]);
    let h = lab.worker(None, caller, 150, &[k.id.0]);
    k.start();
    sys::sleep(5 * MS);
    h.start();
    k.wait_step(1, "callee received the call");
    expect_eq(
        "the callee received the call",
        status(k.block.result(0)),
        Ok(()),
    );
    expect("the caller waits for the reply", !h.block.is_done());
    expect_ok("thread_kill of the callee", sys::thread_kill(k.id));
    h.wait_done("caller of the killed thread");
    expect_err(
        "a caller waiting for a killed thread's reply gets PeerGone",
        status(h.block.result(0)),
        Error::PeerGone,
    );

    // IPC buffers.
    expect_err(
        "thread_set IpcBuffer to a read-only page is BadAddress",
        sys::thread_set(None, ThreadAttribute::IpcBuffer, ROOT_INFO_BASE),
        Error::BadAddress,
    );
    let unmapped = lab.address(spawn::IPC_BUFFER_PAGES);
    expect_err(
        "thread_set IpcBuffer to unmapped memory is BadAddress",
        sys::thread_set(None, ThreadAttribute::IpcBuffer, unmapped),
        Error::BadAddress,
    );
    must(
        "thread_set IpcBuffer back to the root's buffer",
        sys::thread_set(None, ThreadAttribute::IpcBuffer, lab.ipc.address()),
    );
    let z = lab.worker(None, no_buffer, 150, &[]);
    z.start();
    z.wait_step(1, "thread without IPC buffer");
    expect_eq(
        "thread_set IpcBuffer 0 removes the buffer",
        status(z.block.result(0)),
        Ok(()),
    );
    expect_ok(
        "send of a register-only message to a thread without IPC buffer",
        sys::send(z.id, WAIT, &msg(6, [0; 3])),
    );
    z.wait_step(2, "thread without IPC buffer");
    expect_eq(
        "receive of a register-only message works without an IPC buffer",
        (status(z.block.result(1)), z.block.result(2)),
        (Ok(()), 6),
    );
    lab.ipc.write_data(0, &[1; 8]);
    let data = Message {
        tag: MessageTag::new(7, 8, 0),
        words: [0; 3],
    };
    let r = sys::send(z.id, 20 * MS, &data);
    println!("ipc: a data message to a thread without IPC buffer: sender got {r:?}");
    expect(
        "a data message to a thread without IPC buffer is not delivered",
        r.is_err(),
    );
    z.wait_done("thread without IPC buffer");
    expect_err(
        "receive of a data message without an IPC buffer is BadAddress",
        status(z.block.result(3)),
        Error::BadAddress,
    );
}

const L_SEND: usize = 0;
const L_SIGNAL: usize = 1;
const L_WAIT: usize = 2;
const L_SEND_ALLOWED: usize = 3;
const L_ALLOW_ANCESTOR: usize = 4;

worker!(
    /// In the left sibling (with CREATE_TASK). Args: right thread, root task.
    fn left(b, ipc) {
        let right = ThreadId(b.arg(0));
        b.set_code(L_SEND, &sys::send(right, 0, &msg(41, [0; 3])));
        b.set_code(L_SIGNAL, &sys::notify_signal(right, 1));
        b.set_code(
            L_ALLOW_ANCESTOR,
            &sys::task_allow_send(Some(TaskId(b.arg(1))), None),
        );
        b.set_step(1);
        b.set_code(L_WAIT, &sys::notify_wait(1, WAIT));
        b.set_code(
            L_SEND_ALLOWED,
            &sys::send(right, WAIT, &msg(42, [4242, 0, 0])),
        );
    }
);

const R_SEND: usize = 0;
const R_SIGNAL: usize = 1;
const R_RECEIVE: usize = 2;
const R_SENDER: usize = 3;
const R_LABEL: usize = 4;
const R_WORD: usize = 5;

worker!(
    /// In the right sibling. Arg 0: the left thread.
    fn right(b, ipc) {
        let left = ThreadId(b.arg(0));
        b.set_code(R_SEND, &sys::send(left, 0, &msg(43, [0; 3])));
        b.set_code(R_SIGNAL, &sys::notify_signal(left, 1));
        b.set_step(1);
        let r = sys::receive(None, WAIT);
        b.set_code(R_RECEIVE, &r);
        if let Ok(m) = r {
            b.set_result(R_SENDER, m.sender.0);
            b.set_result(R_LABEL, m.message.tag.label() as u64);
            b.set_result(R_WORD, m.message.words[0]);
        }
    }
);

fn rights(lab: &mut Lab) {
    let left_task = lab.task("i-left", BASIC | Abilities::CREATE_TASK, PEER_MCP);
    let right_task = lab.task("i-right", BASIC, PEER_MCP);
    let r = lab.worker(Some(right_task), right, LOW, &[]);
    let l = lab.worker(Some(left_task), left, LOW, &[r.id.0, lab.task.0]);
    r.block.set_arg(0, l.id.0);
    r.start();
    l.start();
    l.wait_step(1, "left sibling");
    r.wait_step(1, "right sibling");
    expect_err(
        "send to a sibling task's thread is NotPermitted by default",
        status(l.block.result(L_SEND)),
        Error::NotPermitted,
    );
    expect_err(
        "notify_signal of a sibling task's thread is NotPermitted by default",
        status(l.block.result(L_SIGNAL)),
        Error::NotPermitted,
    );
    expect_err(
        "task_allow_send naming an ancestor is NotPermitted",
        status(l.block.result(L_ALLOW_ANCESTOR)),
        Error::NotPermitted,
    );
    expect_err(
        "task_allow_send with a nonexistent task is NoSuchObject",
        sys::task_allow_send(Some(TaskId(BOGUS_ID)), None),
        Error::NoSuchObject,
    );
    expect_ok(
        "task_allow_send from one child to its sibling",
        sys::task_allow_send(Some(left_task), Some(right_task)),
    );
    must("notify_signal", sys::notify_signal(l.id, 1));
    l.wait_done("left sibling");
    r.wait_done("right sibling");
    expect_eq(
        "after task_allow_send the sibling's send succeeds",
        status(l.block.result(L_SEND_ALLOWED)),
        Ok(()),
    );
    expect_eq(
        "the sibling received the message",
        (
            status(r.block.result(R_RECEIVE)),
            r.block.result(R_SENDER),
            r.block.result(R_LABEL),
            r.block.result(R_WORD),
        ),
        (Ok(()), l.id.0, 42, 4242),
    );
    expect_err(
        "the reverse direction stays NotPermitted (send)",
        status(r.block.result(R_SEND)),
        Error::NotPermitted,
    );
    expect_err(
        "the reverse direction stays NotPermitted (notify_signal)",
        status(r.block.result(R_SIGNAL)),
        Error::NotPermitted,
    );
    must("task_kill", sys::task_kill(left_task));
    must("task_kill", sys::task_kill(right_task));
}

worker!(
    /// Waits for bits 1 and 2, then polls bit 3.
    fn notified(b, ipc) {
        let first = sys::notify_wait(0b0110, WAIT);
        b.set_code(0, &first);
        b.set_result(1, first.unwrap_or(0));
        let second = sys::notify_wait(0b1000, 0);
        b.set_code(2, &second);
        b.set_result(3, second.unwrap_or(0));
    }
);

fn notifications(lab: &mut Lab, peer: TaskId) {
    expect_ok(
        "notify_signal of the calling thread",
        sys::notify_signal(lab.me, 0b101),
    );
    expect_eq(
        "notify_wait returns the signalled bits of its mask",
        sys::notify_wait(0b001, 0),
        Ok(0b001),
    );
    expect_err(
        "notify_wait cleared the bits it returned",
        sys::notify_wait(0b001, 0),
        Error::TimedOut,
    );
    expect_eq(
        "signalled bits outside a wait's mask stay pending",
        sys::notify_wait(0b100, 0),
        Ok(0b100),
    );
    let (r, took) = timed(|| sys::notify_wait(0b1000, 10 * MS));
    expect_err(
        "notify_wait with a 10 ms timeout and no signal is TimedOut",
        r,
        Error::TimedOut,
    );
    expect(
        "notify_wait with a 10 ms timeout waited at least 10 ms",
        took >= 10 * MS,
    );
    expect_err(
        "notify_signal of a nonexistent thread is NoSuchObject",
        sys::notify_signal(ThreadId(BOGUS_ID), 1),
        Error::NoSuchObject,
    );
    let n = lab.worker(Some(peer), notified, LOW, &[]);
    n.start();
    sys::sleep(5 * MS);
    expect_ok(
        "notify_signal of a waiting child thread",
        sys::notify_signal(n.id, 0b1010),
    );
    n.wait_done("notified thread");
    expect_eq(
        "a waiting thread wakes with the signalled bits of its mask",
        (status(n.block.result(0)), n.block.result(1)),
        (Ok(()), 0b0010),
    );
    expect_eq(
        "the other signalled bit stayed pending for a later wait",
        (status(n.block.result(2)), n.block.result(3)),
        (Ok(()), 0b1000),
    );
}
