//! The loop phase does not touch the heap: ≥ 1,000 ticks of [`Controller::run`] over real
//! iceoryx2 ports, across episode boundaries and a table swap, under a counting global
//! allocator. Its own test binary, so the allocator disturbs no other test; counting is armed
//! per thread, only on the controller's thread (the arm and learner stand-ins run on others).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use rt_controller::testkit::{constant_goal_table, run_kinematic_arm};
use rt_controller::{Controller, ControllerConfig, ExitReason};
use ur5_shared::services::{self, unique_prefix, ServiceNames};
use ur5_shared::{GainTable, StepSample};

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
    static FREES: Cell<u64> = const { Cell::new(0) };
}

fn note(counter: &'static std::thread::LocalKey<Cell<u64>>) {
    // try_with: the allocator may run while thread-locals are torn down.
    let _ = ARMED.try_with(|armed| {
        if armed.get() {
            let _ = counter.try_with(|c| c.set(c.get() + 1));
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(&ALLOCS);
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(&ALLOCS);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(&ALLOCS);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note(&FREES);
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

const T: usize = 100;
const EPISODES: u64 = 12;

/// Publishes version 1 at once and version 2 once episode 3 has started.
fn learner(prefix: String, stop: Arc<AtomicBool>) {
    let names = ServiceNames::new(&prefix);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let gains = services::CONTROLLER_GAINS_QOS
        .open_or_create::<GainTable>(&node, &names.controller_gains().unwrap())
        .unwrap();
    let samples = services::LEARNER_SAMPLES_QOS
        .open_or_create::<StepSample>(&node, &names.learner_samples().unwrap())
        .unwrap();
    let publisher = gains.publisher_builder().create().unwrap();
    let subscriber = samples.subscriber_builder().create().unwrap();
    publisher
        .send_copy(*constant_goal_table(1, T, [0.2, -1.8, 2.2], 0.01))
        .unwrap();
    let mut sent_v2 = false;
    while !stop.load(Ordering::Relaxed) {
        let _ = publisher.update_connections();
        while let Some(s) = subscriber.receive().unwrap() {
            if !sent_v2 && s.episode >= 3 {
                publisher
                    .send_copy(*constant_goal_table(2, T, [-0.2, -1.7, 2.0], 0.01))
                    .unwrap();
                sent_v2 = true;
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn counter_sees_allocations() {
    ARMED.with(|a| a.set(true));
    let v = vec![1u8; 32];
    drop(v);
    ARMED.with(|a| a.set(false));
    assert!(
        ALLOCS.with(|c| c.get()) >= 1 && FREES.with(|c| c.get()) >= 1,
        "the counting allocator is not active"
    );
}

#[test]
fn the_loop_does_not_allocate_across_boundaries_and_a_swap() {
    let prefix = unique_prefix("no-alloc-loop");
    let stop = Arc::new(AtomicBool::new(false));
    let arm = {
        let (prefix, stop) = (prefix.clone(), stop.clone());
        std::thread::spawn(move || {
            run_kinematic_arm(&prefix, 0.1, std::f64::consts::PI, &stop)
                .unwrap()
                .commands
        })
    };
    let learner = {
        let (prefix, stop) = (prefix.clone(), stop.clone());
        std::thread::spawn(move || learner(prefix, stop))
    };

    // Setup phase: may allocate.
    let cfg = ControllerConfig {
        prefix,
        episodes: EPISODES,
        wait_for_learner: true,
        // The per-episode report goes through the loop too.
        episode_report: true,
        ..ControllerConfig::default()
    };
    let mut controller = Controller::setup(cfg).expect("setup");
    let never = AtomicBool::new(false);

    // Loop phase: counted.
    ALLOCS.with(|c| c.set(0));
    FREES.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let t0 = Instant::now();
    let reason = controller.run(&never);
    let wall = t0.elapsed();
    ARMED.with(|a| a.set(false));
    let (allocs, frees) = (ALLOCS.with(|c| c.get()), FREES.with(|c| c.get()));

    stop.store(true, Ordering::Relaxed);
    let commands = arm.join().unwrap();
    learner.join().unwrap();
    let s = controller.stats();
    assert_eq!(reason, ExitReason::EpisodesDone);
    assert_eq!(s.episodes_completed, EPISODES);
    assert!(s.ticks >= 1000, "only {} ticks", s.ticks);
    assert_eq!(
        s.swaps, 2,
        "version 1 at the first boundary, version 2 later"
    );
    assert_eq!(
        s.faults.stale_state + s.faults.arm_fault + s.faults.non_finite_action,
        0
    );
    assert!(commands >= s.ticks);
    assert_eq!(
        (allocs, frees),
        (0, 0),
        "the loop allocated {allocs} and freed {frees} times over {} ticks ({wall:?})",
        s.ticks
    );
}
