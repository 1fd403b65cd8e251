//! Partition `handled` (scenario `apex_error_handler`): the partition's error handler on
//! the kernel. `faulty` (priority 10) raises two application errors; the handler (at the
//! MCP) runs at once for each, reads it with GET_ERROR_STATUS until NO_ACTION, and shows
//! what an error handler may not do. For the error `end` it raises an error itself, which
//! goes to syssw's health monitor (configured as `shutdown_success`).
//!
//! Every line starts with `handled:`.

use apex::Warden;
use apex::a653rs::bindings::{
    self as b, ApexErrorP1, ApexErrorP4, ApexProcessP1, ApexProcessP4, ApexTimeP1, ErrorReturnCode,
};
use apex::a653rs::prelude::{Deadline, StartContext};
use apex::codes::{apex_name, name_bytes};
use apex::user_rt::println;
use core::sync::atomic::{AtomicU32, Ordering};

const MS: i64 = 1_000_000;
const INFINITE: i64 = b::INFINITE_TIME_VALUE;

/// Errors the handler has taken.
static HANDLED: AtomicU32 = AtomicU32::new(0);

fn code<T>(result: Result<T, ErrorReturnCode>) -> Option<ErrorReturnCode> {
    result.err()
}

fn raise(text: &[u8]) -> Result<(), ErrorReturnCode> {
    <Warden as ApexErrorP4>::raise_application_error(b::ErrorCode::ApplicationError, text)
}

pub fn create(_ctx: &mut StartContext<Warden>) {
    <Warden as ApexErrorP1>::create_error_handler(handler as b::SystemAddress, 16 * 1024)
        .expect("CREATE_ERROR_HANDLER");
    println!(
        "handled: init CREATE_ERROR_HANDLER again: {:?}",
        code(<Warden as ApexErrorP1>::create_error_handler(
            handler as b::SystemAddress,
            16 * 1024
        ))
    );
    let attributes = b::ApexProcessAttribute {
        period: INFINITE,
        time_capacity: INFINITE,
        entry_point: faulty,
        stack_size: 16 * 1024,
        base_priority: 10,
        deadline: Deadline::Soft,
        name: apex_name("faulty"),
    };
    let id = <Warden as ApexProcessP4>::create_process(&attributes).expect("CREATE_PROCESS");
    <Warden as ApexProcessP4>::start(id).expect("START");
}

extern "C" fn faulty() {
    println!(
        "handled: faulty: GET_ERROR_STATUS {:?}; RAISE_APPLICATION_ERROR with a {}-byte message {:?}, as DEADLINE_MISSED {:?}",
        code(<Warden as ApexErrorP1>::get_error_status()),
        b::MAX_ERROR_MESSAGE_SIZE + 1,
        code(raise(&[b'x'; b::MAX_ERROR_MESSAGE_SIZE + 1])),
        code(<Warden as ApexErrorP4>::raise_application_error(
            b::ErrorCode::DeadlineMissed,
            b"no"
        ))
    );
    let result = raise(b"first");
    // The handler (above this process) ran before RAISE_APPLICATION_ERROR returned.
    println!(
        "handled: faulty: RAISE_APPLICATION_ERROR first {:?}, handled {}",
        code(result),
        HANDLED.load(Ordering::Relaxed)
    );
    let _ = raise(b"end");
    println!("handled: faulty: still running after end");
}

extern "C" fn handler() {
    loop {
        let status = match <Warden as ApexErrorP1>::get_error_status() {
            Ok(status) => status,
            Err(e) => {
                println!("handled: handler: GET_ERROR_STATUS then {e:?}");
                break;
            }
        };
        HANDLED.fetch_add(1, Ordering::Relaxed);
        let message = &status.message[..status.length as usize];
        let failed = <Warden as ApexProcessP1>::get_process_status(status.failed_process_id)
            .map(|s| s.attributes.name);
        let failed = failed.as_ref().map_or(&b"?"[..], |n| name_bytes(n));
        println!(
            "handled: handler: {:?} from {} message {:?}",
            status.error_code,
            core::str::from_utf8(failed).unwrap_or("?"),
            core::str::from_utf8(message).unwrap_or("?"),
        );
        if message == b"first" {
            println!(
                "handled: handler: LOCK_PREEMPTION {:?}; TIMED_WAIT {:?}; GET_MY_ID {:?}",
                code(<Warden as ApexProcessP1>::lock_preemption()),
                code(<Warden as ApexTimeP1>::timed_wait(MS)),
                <Warden as ApexProcessP1>::get_my_id().is_ok()
            );
        }
        if message == b"end" {
            // The handler's own error goes to the health monitor.
            let _ = raise(b"handler done");
        }
    }
}
