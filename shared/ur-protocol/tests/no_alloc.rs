//! The client's steady-state path (stream decode, data-package decode into the state, reverse
//! command encode) performs no heap allocation: counted by a global allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use ur_protocol::recipe::OutputRecipe;
use ur_protocol::rtde::Protocol;
use ur_protocol::stream::FrameDecoder;
use ur_protocol::{ControlMode, ReverseCommand, RobotMessage, RobotState};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn client_cycle_does_not_allocate() {
    // Setup (may allocate): recipe, buffers, a stream of 100 packages from the "robot".
    let names = "timestamp,actual_q,actual_qd,robot_mode,safety_mode,runtime_state,speed_scaling";
    let types = "DOUBLE,VECTOR6D,VECTOR6D,INT32,INT32,UINT32,DOUBLE";
    let recipe = OutputRecipe::from_answer(names, 1, types).unwrap();
    let mut stream = Vec::new();
    let mut buf = [0u8; 512];
    for i in 0..100 {
        let s = RobotState {
            timestamp: i as f64 * 0.002,
            actual_q: [i as f64 * 1e-3; 6],
            robot_mode: 7,
            safety_mode: 1,
            ..Default::default()
        };
        let n = s.encode_package(&recipe, &mut buf).unwrap();
        stream.extend_from_slice(&buf[..n]);
    }
    let mut dec = FrameDecoder::<4096>::new();
    let mut state = RobotState::default();
    let mut packages = 0;
    let mut sent = 0usize;

    let before = ALLOCS.load(Ordering::Relaxed);
    // Reads of 37 bytes: packages split and merged.
    for chunk in stream.chunks(37) {
        dec.push(chunk);
        while let Ok(Some(f)) = dec.next_frame() {
            let m = RobotMessage::decode(&f, Protocol::V2).unwrap();
            if state.update(&recipe, &m).unwrap() {
                packages += 1;
                let cmd = ReverseCommand {
                    timeout_ms: 20,
                    q: state.actual_q,
                    mode: ControlMode::Servoj,
                };
                sent += cmd.encode().unwrap().len();
            }
        }
    }
    let allocs = ALLOCS.load(Ordering::Relaxed) - before;
    assert_eq!(allocs, 0, "the client cycle allocated {allocs} times");
    assert_eq!(packages, 100);
    assert_eq!(sent, 3200);
    assert_eq!(state.actual_q[0], 0.099);
}
