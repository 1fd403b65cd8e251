//! Host tests of `kernel/src/thread.rs` (a child module of it: `super` is that module).

use super::{FpuState, Thread};
use abi::syscall::syscall_answer;

#[test]
fn a_sanitized_fpu_image_keeps_writable_mxcsr_bits_only() {
    let mut current = FpuState::initial();
    let mut image = [0xffu8; 512];
    assert_eq!(
        &current.sanitized(image).0[24..32],
        &[0xbf, 0xff, 0, 0, 0, 0, 0, 0]
    );
    current.0[28..32].copy_from_slice(&0xffffu32.to_le_bytes());
    image[24..28].copy_from_slice(&0x1f80u32.to_le_bytes());
    let loaded = current.sanitized(image);
    assert_eq!(&loaded.0[24..32], &[0x80, 0x1f, 0, 0, 0xff, 0xff, 0, 0]);
    assert_eq!(loaded.0[0..24], image[0..24]);
}

#[test]
fn a_thread_answers_the_one_forwarded_call_it_was_given_and_no_other() {
    let mut thread = Thread::FREE;
    thread.context_mut().rax = 0;
    assert!(!thread.answered(), "no answer set: call 0 is forwarded");
    thread.set_syscall_answer(syscall_answer(39, 7));
    for other in [0, 38, 40, 39 | 1 << 32, u64::MAX] {
        thread.context_mut().rax = other;
        assert!(!thread.answered());
        assert_eq!(
            thread.context().rax,
            other,
            "a forwarded call keeps its number"
        );
    }
    thread.context_mut().rax = 39;
    assert!(thread.answered());
    assert_eq!(thread.context().rax, 7);
    thread.set_syscall_answer(syscall_answer(39, u32::MAX));
    thread.context_mut().rax = 39;
    assert!(thread.answered());
    assert_eq!(thread.context().rax, u64::from(u32::MAX), "zero-extended");
    thread.set_syscall_answer(0);
    thread.context_mut().rax = 39;
    assert!(!thread.answered());
}
