//! The per-tick path does not touch the heap: `controller_action` (and the other calls the
//! controller makes per tick or per table: `validate`, `copy_from`, `state_vector`) are run
//! under a counting global allocator. It lives in its own test binary so the allocator does
//! not affect other tests; counting is per thread, so parallel tests here do not interfere.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::{
    controller_action, state_vector, ArmState, GainBounds, GainTable, StateLayout, NO_NOISE,
};

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    // try_with: the allocator may run while thread-locals are being torn down.
    let _ = ARMED.try_with(|armed| {
        if armed.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note();
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Number of heap operations (alloc, realloc, dealloc) on this thread while `f` runs.
fn heap_ops<R>(f: impl FnOnce() -> R) -> (u64, R) {
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let r = f();
    ARMED.with(|a| a.set(false));
    (COUNT.with(|c| c.get()), r)
}

fn filled_table(layout: &StateLayout, seed: u64) -> Box<GainTable> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut table = GainTable::new_boxed_for(layout);
    table.set_version(seed);
    table.set_horizon(100).unwrap();
    for t in 0..100 {
        let mut st = table.step_mut(t);
        for v in st.k_mat.iter_mut() {
            *v = rng.random_range(-1.0..1.0);
        }
        for i in 0..layout.du() {
            st.k_vec[i] = rng.random_range(-1.0..1.0);
            st.a_hat[i] = rng.random_range(-1.0..1.0);
            for j in 0..i {
                st.set_l(i, j, rng.random_range(-0.1..0.1));
            }
            st.set_l(i, i, 0.5);
        }
    }
    table.seal();
    table
}

#[test]
fn counter_sees_allocations() {
    let (n, v) = heap_ops(|| vec![1u8; 16]);
    drop(v);
    assert!(n >= 1, "the counting allocator is not active");
}

/// At the reaching task's dimensions and at the whole arm's with a pose (dX = 30, dU = 6).
#[test]
fn controller_action_does_not_allocate() {
    for layout in [StateLayout::REACH3, StateLayout::POSE6] {
        let (dx, du) = (layout.dx(), layout.du());
        let table = filled_table(&layout, 3);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let states: Vec<Vec<f64>> = (0..1000)
            .map(|_| (0..dx).map(|_| rng.random_range(-2.0..2.0)).collect())
            .collect();
        let noise: Vec<Vec<f64>> = (0..1000)
            .map(|_| (0..du).map(|_| rng.random_range(-2.0..2.0)).collect())
            .collect();
        let mut a = vec![0.0; du];
        let mut checksum = 0.0;
        let (n, ()) = heap_ops(|| {
            for rep in 0..100 {
                for (k, (s, eps)) in states.iter().zip(&noise).enumerate() {
                    let t = (k + rep) % 100;
                    let eps: &[f64] = if k % 2 == 0 { eps } else { &NO_NOISE };
                    controller_action(&table, t, s, eps, &mut a).unwrap();
                    checksum += a[0];
                }
            }
            // The error paths do not allocate either.
            assert!(controller_action(&table, 100, &states[0], &NO_NOISE, &mut a).is_err());
            assert!(controller_action(&table, 0, &states[0][1..], &NO_NOISE, &mut a).is_err());
        });
        assert!(checksum.is_finite());
        assert_eq!(
            n, 0,
            "controller_action allocated {n} times over 100 000 calls ({layout})"
        );
    }
}

#[test]
fn table_handling_and_state_assembly_do_not_allocate() {
    let incoming = filled_table(&StateLayout::REACH3, 5);
    let mut buffers = [GainTable::new_boxed(), GainTable::new_boxed()];
    let bounds = GainBounds::default();
    let arm = ArmState::of_joints(&[0.1, 0.2, 0.3], &[0.0; 3], [0.4, 0.1, 0.3], [0.0; 3]);
    let mut pose = ArmState::of_joints(&[0.1; 6], &[0.0; 6], [0.0; 3], [0.0; 3]);
    pose.set_points(&[[0.4, 0.1, 0.3]; 3], &[[0.0; 3]; 3]);
    let targets = [[0.4, 0.1, 0.3], [0.3, 0.1, 0.3], [0.4, 0.0, 0.3]];
    let (n, ()) = heap_ops(|| {
        for k in 0..20 {
            incoming.validate(&bounds).unwrap();
            buffers[k % 2].copy_from(&incoming);
            let s = arm.state_vector(&[0.5, 0.0, 0.3]);
            let (q, qd) = (
                [arm.q[0], arm.q[1], arm.q[2]],
                [arm.qd[0], arm.qd[1], arm.qd[2]],
            );
            let s2 = state_vector(
                &q,
                &qd,
                &arm.points[0],
                &arm.point_vels[0],
                &[0.5, 0.0, 0.3],
            );
            assert_eq!(s, s2);
            let mut s3 = [0.0; 30];
            pose.fill_state(&StateLayout::POSE6, &targets, &mut s3);
            assert_eq!(s3[StateLayout::POSE6.point(2)], [0.0, 0.1, 0.0]);
        }
        // Rejections build their error without formatting anything.
        buffers[0].step_mut(7).set_l(0, 1, 1.0);
        buffers[0].seal();
        assert!(buffers[0].validate(&bounds).is_err());
        buffers[1].version += 1;
        assert!(buffers[1].validate(&bounds).is_err());
    });
    assert_eq!(n, 0, "table handling allocated {n} times");
}
