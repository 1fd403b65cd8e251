//! The QEMU scenarios' tests, one module per area, in one test program so that the test
//! harness keeps every CPU busy from the first scenario to the last (a program per area
//! left CPUs idle at each program's slowest test). Each test `NAME` boots scenario
//! `tests/scenarios/NAME.toml`, which `cargo xtask test [FILTER]` builds first.

mod a653rs;
mod apex;
mod attack;
mod blk;
mod boot;
mod devices;
mod dma;
mod guest;
mod guest_bash;
mod guest_busybox;
mod guest_e2fsck;
mod guest_linux;
mod guest_memory;
mod guest_rust_std;
mod iec61499;
mod iec61499_tcp;
mod kernel;
mod loader;
mod net;
mod net_forte;
mod net_guest;
mod net_plc;
mod net_sockets;
mod net_storm;
mod net_two_guests;
mod pci;
mod plant;
mod plc;
mod power_cut;
mod smp;
mod store;
mod syssw;
mod system;
mod system_ports;
mod time;
mod user;
