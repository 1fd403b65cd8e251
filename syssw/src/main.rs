//! syssw: the system software, the root task (ring 3).
//!
//! It will read the static configuration from the system image and distribute every
//! resource (memory, I/O ports, time windows, kernel memory) to the partitions, own the
//! inter-partition ports and the health monitor. It must never allocate after start-up.
//!
//! Stage: the kernel starts it as the root task with the system image mapped read-only; it
//! checks the image and reports what it holds. Partitions come with the configuration.
#![no_std]
#![no_main]
#![forbid(unsafe_op_in_unsafe_fn)]
#![deny(unsafe_code)]

use user_rt::abi::sysimg::SystemImage;
use user_rt::println;

user_rt::entry!(main);

fn main(image_base: u64, image_len: u64) {
    let bytes = user_rt::system_image(image_base, image_len);
    match SystemImage::parse(bytes) {
        Ok(image) => println!(
            "syssw: root task started; system image {} bytes, {} entries",
            image.size(),
            image.len()
        ),
        Err(e) => {
            println!("syssw: system image rejected: {e}");
            let _ = user_rt::sys::system_halt(false);
        }
    }
}
