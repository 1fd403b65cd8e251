//! Host tests of `kernel/src/thread.rs` (a child module of it: `super` is that module).

use super::FpuState;

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
