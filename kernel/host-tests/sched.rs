//! Host tests of the scheduler's ready queues (`kernel/src/sched.rs`); kept outside `src` so that the
//! ring-0 code budget counts only what runs in ring 0.

use super::*;
use proptest::prelude::*;

#[test]
fn highest_priority_first_then_fifo() {
    let mut q = RunQueues::<8>::new();
    q.enqueue(1, 10, 0);
    q.enqueue(2, 20, 0);
    q.enqueue(3, 20, 0);
    assert_eq!(q.choose(None), Some(2));
    q.rotate(2);
    assert_eq!(q.choose(None), Some(3));
    q.remove(3);
    q.remove(2);
    assert_eq!(q.choose(None), Some(1));
    q.remove(1);
    assert_eq!(q.choose(None), None);
}

#[test]
fn only_background_and_active_partition_are_eligible() {
    let mut q = RunQueues::<8>::new();
    q.enqueue(1, 50, 1);
    q.enqueue(2, 10, 0);
    q.enqueue(3, 99, 2);
    assert_eq!(q.choose(None), Some(2));
    assert_eq!(q.choose(Some(1)), Some(1));
    assert_eq!(q.choose(Some(2)), Some(3));
    q.enqueue(4, 50, 0);
    assert_eq!(
        q.choose(Some(1)),
        Some(1),
        "equal priority: active partition wins"
    );
    q.enqueue(5, 51, 0);
    assert_eq!(
        q.choose(Some(1)),
        Some(5),
        "a higher background thread wins"
    );
}

/// Operations on the queues, checked against a plain list model.
#[derive(Debug, Clone)]
enum Op {
    Enqueue(usize, u8, u8),
    Remove(usize),
    Rotate(usize),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        (0..16usize, any::<u8>(), 0..3u8).prop_map(|(t, p, tp)| Op::Enqueue(t, p, tp)),
        (0..16usize).prop_map(Op::Remove),
        (0..16usize).prop_map(Op::Rotate),
    ]
}

proptest! {
    #[test]
    fn matches_a_list_model(ops in proptest::collection::vec(op(), 0..200), active in 0..3u8) {
        let mut q = RunQueues::<16>::new();
        // Model: arrival order of (thread, priority, partition).
        let mut model: Vec<(usize, u8, u8)> = Vec::new();
        for op in ops {
            match op {
                Op::Enqueue(t, p, tp) => {
                    q.enqueue(t, p, tp);
                    if !model.iter().any(|e| e.0 == t) { model.push((t, p, tp)); }
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
            let eligible = |e: &&(usize, u8, u8)| e.2 == 0 || (active != 0 && e.2 == active);
            let best = model.iter().filter(eligible).map(|e| e.1).max();
            let expected = best.map(|b| {
                // Active partition wins ties; FIFO within a partition and priority.
                model.iter().filter(eligible).filter(|e| e.1 == b)
                    .min_by_key(|e| (e.2 == 0, model.iter().position(|x| x.0 == e.0)))
                    .unwrap().0
            });
            prop_assert_eq!(q.choose(Some(active)), expected);
        }
    }
}
