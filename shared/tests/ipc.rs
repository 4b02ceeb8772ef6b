//! The payload types go through iceoryx2 0.9.3 publish–subscribe unchanged, under a unique
//! service prefix so this test can run next to any other.

use iceoryx2::prelude::*;
use ur5_shared::services::{unique_prefix, ServiceNames};
use ur5_shared::{
    ArmCommand, ArmState, CommandKind, GainBounds, GainTable, StepSample, DU, DX, MAX_HORIZON,
};

fn round_trip<T: core::fmt::Debug + Copy + PartialEq + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    name: &ServiceName,
    value: T,
) {
    let service = node
        .service_builder(name)
        .publish_subscribe::<T>()
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .enable_safe_overflow(true)
        .open_or_create()
        .unwrap();
    let publisher = service.publisher_builder().create().unwrap();
    let subscriber = service.subscriber_builder().create().unwrap();
    publisher.send_copy(value).unwrap();
    let sample = subscriber.receive().unwrap().expect("no sample received");
    assert_eq!(*sample, value);
}

#[test]
fn payloads_round_trip_through_iceoryx2() {
    let names = ServiceNames::new(&unique_prefix("shared-ipc"));
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();

    let state = ArmState {
        seq: 1,
        stamp_ns: 123,
        ..ArmState::of_joints(
            &[0.1, -1.2, 2.0, 0.3, 0.4, 0.5],
            &[0.0; 6],
            [0.4, 0.1, 0.3],
            [0.0; 3],
        )
    };
    round_trip(&node, &names.arm_state().unwrap(), state);
    round_trip(
        &node,
        &names.arm_command().unwrap(),
        ArmCommand::goal_angles(2, 456, 0, [0.1, 0.2, 0.3]),
    );
    round_trip(
        &node,
        &names.learner_samples().unwrap(),
        StepSample {
            table_version: 3,
            t: 99,
            noise: 1,
            ..StepSample::default()
        }
        .with_parts(&[0.5; DX], &[0.25; DU], &[0.2; DU]),
    );
    assert_eq!(
        ArmCommand::reset(1, 0, 0, [0.0; 3]).kind(),
        Ok(CommandKind::Reset)
    );
}

#[test]
fn gain_table_is_built_in_a_loaned_sample_and_validates_on_the_other_side() {
    let names = ServiceNames::new(&unique_prefix("shared-ipc-gains"));
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let service = node
        .service_builder(&names.controller_gains().unwrap())
        .publish_subscribe::<GainTable>()
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .enable_safe_overflow(true)
        .open_or_create()
        .unwrap();
    let publisher = service.publisher_builder().create().unwrap();
    let subscriber = service.subscriber_builder().create().unwrap();

    for version in 1..=3u64 {
        let mut sample = publisher.loan_uninit().unwrap();
        let table = GainTable::init_zeroed(sample.payload_mut());
        table.set_version(version);
        table.set_horizon(MAX_HORIZON).unwrap();
        for t in 0..MAX_HORIZON {
            let mut st = table.step_mut(t);
            st.set_k(1, 7, t as f64 * 0.01);
            st.a_hat.copy_from_slice(&[0.1, 0.2, version as f64]);
            st.chol
                .copy_from_slice(&[0.5, 0.0, 0.0, 0.1, 0.5, 0.0, 0.0, 0.1, 0.5]);
        }
        table.seal();
        // SAFETY: init_zeroed initialised the payload.
        unsafe { sample.assume_init() }.send().unwrap();
    }

    // Safe overflow with a buffer of 1: only the newest table is waiting.
    let received = subscriber.receive().unwrap().expect("no table received");
    received.validate(&GainBounds::default()).unwrap();
    assert_eq!(received.version, 3);
    assert_eq!(received.step(127).k(1, 7), 1.27);
    let mut buffer = GainTable::new_boxed();
    buffer.copy_from(&received);
    assert_eq!(*buffer, *received);
    assert!(subscriber.receive().unwrap().is_none());
}
