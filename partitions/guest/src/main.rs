//! The guest partition program (being built up: see the library's documentation).
#![no_std]
#![no_main]

user_rt::entry!(main);

fn main(_start: u64, _: u64) {
    user_rt::println!("guest: no process support in this build yet");
}
