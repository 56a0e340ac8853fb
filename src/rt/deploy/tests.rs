//! Unit tests of the configuration flow: buffer sizing by the first producer, shared buffers,
//! and the topology errors (why here: they drive [`Configure`] on a bare [`Registry`]).

use super::registry::Registry;
use super::{Configure, TopologyErrorKind};
use crate::rt::buffer::FullPolicy;
use crate::rt::interface::{PortDirection, TaskInterface};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Runs `f` as task `task`'s configure hook on `reg`; returns what `f` returns.
fn configure<R>(
    reg: &mut Registry,
    iface: &mut TaskInterface,
    task: &str,
    f: impl FnOnce(&mut Configure<'_>) -> R,
) -> R {
    let mut ctx = Configure {
        task,
        reg,
        iface,
        wake: Arc::new(AtomicBool::new(false)),
    };
    f(&mut ctx)
}

#[test]
fn a_buffer_named_first_by_its_consumer_is_sized_by_its_first_producer() {
    let mut reg = Registry::default();
    let (mut ci, mut pi) = (TaskInterface::default(), TaskInterface::default());
    let mut r = configure(&mut reg, &mut ci, "c", |c| c.buffer_in::<u32>("q"));
    assert_eq!(
        (r.capacity(), r.policy()),
        (0, None),
        "unsized until a producer"
    );
    let w = configure(&mut reg, &mut pi, "p", |c| {
        c.buffer_out::<u32>("q", 3, FullPolicy::DropOldest)
    });
    assert_eq!(
        (r.capacity(), r.policy()),
        (4, Some(FullPolicy::DropOldest))
    );
    w.push(7);
    assert_eq!(r.pop(), Some(7));
    assert_eq!(reg.check(), []);
    assert_eq!(reg.warnings(), Vec::<String>::new());
    assert_eq!(
        (ci.ports[0].direction, pi.ports[0].direction),
        (PortDirection::Input, PortDirection::Output)
    );
    assert_eq!(pi.ports[0].object, "q");
}

#[test]
fn agreeing_producers_share_one_buffer_and_a_second_consumer_is_detached() {
    let mut reg = Registry::default();
    let mut iface = TaskInterface::default();
    let w1 = configure(&mut reg, &mut iface, "p1", |c| {
        c.buffer_out::<u8>("q", 8, FullPolicy::DropNewest)
    });
    let w2 = configure(&mut reg, &mut iface, "p2", |c| {
        c.buffer_out::<u8>("q", 8, FullPolicy::DropNewest)
    });
    let mut r1 = configure(&mut reg, &mut iface, "c1", |c| c.buffer_in::<u8>("q"));
    let mut r2 = configure(&mut reg, &mut iface, "c2", |c| c.buffer_in::<u8>("q"));
    w1.push(1);
    w2.push(2);
    assert_eq!((r1.pop(), r1.pop()), (Some(1), Some(2)));
    assert_eq!(r2.pop(), None, "the second consumer's reader is detached");
    let errors = reg.check();
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert_eq!(
        (errors[0].task.as_str(), errors[0].port.as_str()),
        ("c2", "q")
    );
    assert_eq!(
        errors[0].kind,
        TopologyErrorKind::MultipleConsumers(vec!["c1".into(), "c2".into()])
    );
}

#[test]
fn conflicts_mismatches_and_missing_ends_are_reported() {
    let mut reg = Registry::default();
    let mut iface = TaskInterface::default();
    configure(&mut reg, &mut iface, "p1", |c| {
        c.buffer_out::<u8>("q", 8, FullPolicy::DropNewest)
    });
    let w = configure(&mut reg, &mut iface, "p2", |c| {
        c.buffer_out::<u8>("q", 8, FullPolicy::DropOldest)
    });
    // The conflicting producer still writes into the one buffer (sized as first declared).
    let mut r = configure(&mut reg, &mut iface, "c", |c| c.buffer_in::<u8>("q"));
    w.push(5);
    assert_eq!(
        (r.pop(), r.policy()),
        (Some(5), Some(FullPolicy::DropNewest))
    );
    configure(&mut reg, &mut iface, "x", |c| {
        c.buffer_out::<u16>("q", 8, FullPolicy::DropNewest)
    });
    configure(&mut reg, &mut iface, "lonely", |c| {
        c.buffer_in::<u8>("void")
    });
    configure(&mut reg, &mut iface, "tracer", |c| {
        c.buffer_out::<u8>("trace", 8, FullPolicy::DropOldest)
    });
    let errors: Vec<String> = reg.check().iter().map(ToString::to_string).collect();
    assert_eq!(
        errors,
        [
            "task 'p2' buffer output 'q': capacity 8 DropOldest but task 'p1' declared \
             capacity 8 DropNewest",
            "task 'x' port 'q': type u16 but the object has type u8",
            "task 'lonely' buffer input 'void': no task produces into it",
        ]
    );
    assert_eq!(
        reg.warnings(),
        [
            "buffer 'trace' (output of task 'tracer') has no consumer: once full, every push \
          is dropped"
        ]
    );
}
