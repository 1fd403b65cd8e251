//! Host tests of the scheduler's ready queues (`kernel/src/sched.rs`); kept outside `src` so that the
//! ring-0 code budget counts only what runs in ring 0.

use super::*;
use proptest::prelude::*;

fn at(priority: u8, partition: u8, cpu: u8) -> Place {
    Place {
        priority,
        partition,
        cpu,
    }
}

#[test]
fn highest_priority_first_then_fifo() {
    let mut q = RunQueues::<8>::new();
    q.enqueue(1, at(10, 0, 0));
    q.enqueue(2, at(20, 0, 0));
    q.enqueue(3, at(20, 0, 0));
    assert_eq!(q.choose(0, None), Some(2));
    q.rotate(2);
    assert_eq!(q.choose(0, None), Some(3));
    q.remove(3);
    q.remove(2);
    assert_eq!(q.choose(0, None), Some(1));
    q.remove(1);
    assert_eq!(q.choose(0, None), None);
}

#[test]
fn only_background_and_active_partition_are_eligible() {
    let mut q = RunQueues::<8>::new();
    q.enqueue(1, at(50, 1, 0));
    q.enqueue(2, at(10, 0, 0));
    q.enqueue(3, at(99, 2, 0));
    assert_eq!(q.choose(0, None), Some(2));
    assert_eq!(q.choose(0, Some(1)), Some(1));
    assert_eq!(q.choose(0, Some(2)), Some(3));
    q.enqueue(4, at(50, 0, 0));
    assert_eq!(
        q.choose(0, Some(1)),
        Some(1),
        "equal priority: active partition wins"
    );
    q.enqueue(5, at(51, 0, 0));
    assert_eq!(
        q.choose(0, Some(1)),
        Some(5),
        "a higher background thread wins"
    );
}

#[test]
fn a_cpu_chooses_among_its_own_threads_only() {
    let mut q = RunQueues::<8>::new();
    q.enqueue(1, at(50, 1, 0));
    q.enqueue(2, at(90, 1, 1));
    q.enqueue(3, at(10, 0, 1));
    assert_eq!(q.choose(0, Some(1)), Some(1));
    assert_eq!(q.choose(1, Some(1)), Some(2));
    assert_eq!(
        q.choose(1, None),
        Some(3),
        "each CPU has its own background"
    );
    assert_eq!(q.choose(2, Some(1)), None);
    q.remove(2);
    assert_eq!(q.choose(1, Some(1)), Some(3));
}

/// Operations on the queues, checked against a plain list model.
#[derive(Debug, Clone)]
enum Op {
    Enqueue(usize, u8, u8, u8),
    Remove(usize),
    Rotate(usize),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        (0..16usize, any::<u8>(), 0..3u8, 0..2u8)
            .prop_map(|(t, p, tp, cpu)| Op::Enqueue(t, p, tp, cpu)),
        (0..16usize).prop_map(Op::Remove),
        (0..16usize).prop_map(Op::Rotate),
    ]
}

proptest! {
    #[test]
    fn matches_a_list_model(ops in proptest::collection::vec(op(), 0..200), active in 0..3u8) {
        let mut q = RunQueues::<16>::new();
        // Model: arrival order of (thread, priority, partition, cpu).
        let mut model: Vec<(usize, u8, u8, u8)> = Vec::new();
        for op in ops {
            match op {
                Op::Enqueue(t, p, tp, cpu) => {
                    q.enqueue(t, at(p, tp, cpu));
                    if !model.iter().any(|e| e.0 == t) { model.push((t, p, tp, cpu)); }
                }
                Op::Remove(t) => { q.remove(t); model.retain(|e| e.0 != t); }
                Op::Rotate(t) => {
                    q.rotate(t);
                    if let Some(i) = model.iter().position(|e| e.0 == t) {
                        let e = model.remove(i);
                        model.push(e);
                    }
                }
            }
            for cpu in 0..2u8 {
                let eligible = |e: &&(usize, u8, u8, u8)| {
                    e.3 == cpu && (e.2 == 0 || (active != 0 && e.2 == active))
                };
                let best = model.iter().filter(eligible).map(|e| e.1).max();
                let expected = best.map(|b| {
                    // Active partition wins ties; FIFO within a partition and priority.
                    model.iter().filter(eligible).filter(|e| e.1 == b)
                        .min_by_key(|e| (e.2 == 0, model.iter().position(|x| x.0 == e.0)))
                        .unwrap().0
                });
                prop_assert_eq!(q.choose(cpu as usize, Some(active)), expected);
            }
        }
    }
}
