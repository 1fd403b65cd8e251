//! Time-partitioning scenarios (the user-mode test program in mode `windows`, and
//! `irq-ports` for interrupts and I/O ports at user level).

use scenarios::passes;

#[test]
fn time_windows() {
    passes(
        "time_windows",
        "windows",
        &[
            "schedule_set with overlapping windows is InvalidArgument",
            "schedule_set with a window for TP0 is InvalidArgument",
            "TP0 gets exactly the gaps while TP1 and TP2 use their windows",
            "every frame's TP2 window was recorded",
            "TP2 ran outside its window in at most 2% of the frames (timer interrupts late on a loaded host)",
            "at most 2% of TP2's windows were lost (to host stalls longer than a window)",
            "TP2's window starts are punctual while TP1 spins (median < 100 us, p99 < 500 us)",
            "a TP0 thread cannot raise itself above its MCP",
            "the background thread ran (in the gaps)",
            "the background thread at its MCP never ran inside TP1's or TP2's busy windows",
            "TP0 gets the idle part of TP1's window, TP2's unused window and the gaps",
            "the background thread never ran in TP1's busy part",
            "with TP0 idle too, the unused time is idle time, not given to TP1",
            "schedule_set of the running schedule's slot is NotPermitted",
            "TP3 (schedule 1) first runs at the frame boundary plus its window offset, not before",
            "TP1 ran in the frame the switch was requested in, and not after its end",
            "partition_info reports TP3's window of the new schedule",
        ],
    );
}
