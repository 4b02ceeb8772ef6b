//! Property tests of the RTDE stream decoder (docs/design.md §3.10): any split or merge of a
//! valid stream decodes to the same packages; arbitrary bytes never panic.

use proptest::prelude::*;
use ur_protocol::recipe::OutputRecipe;
use ur_protocol::rtde::{level, ControllerVersion, Frame, Protocol, TextMessage};
use ur_protocol::stream::FrameDecoder;
use ur_protocol::{ClientMessage, ReverseCommand, RobotMessage, RobotState};

const RECIPE_NAMES: &str =
    "timestamp,actual_q,actual_qd,robot_mode,safety_mode,runtime_state,speed_scaling,joint_mode";
const RECIPE_TYPES: &str = "DOUBLE,VECTOR6D,VECTOR6D,INT32,INT32,UINT32,DOUBLE,VECTOR6INT32";

fn recipe() -> OutputRecipe {
    OutputRecipe::from_answer(RECIPE_NAMES, 1, RECIPE_TYPES).unwrap()
}

/// One package a controller may send, as an owned description.
#[derive(Clone, Debug)]
enum Pkg {
    Data(f64, [f64; 6], i32),
    Text(String),
    Version(u32),
    Start(bool),
    Setup(u8),
}

fn pkg() -> impl Strategy<Value = Pkg> {
    prop_oneof![
        4 => (any::<f64>(), prop::array::uniform6(-10.0f64..10.0), -1i32..9)
            .prop_map(|(t, q, m)| Pkg::Data(t, q, m)),
        1 => "[ -~]{0,80}".prop_map(Pkg::Text),
        1 => (0u32..10).prop_map(Pkg::Version),
        1 => any::<bool>().prop_map(Pkg::Start),
        1 => any::<u8>().prop_map(Pkg::Setup),
    ]
}

/// Encodes a package into the stream.
fn encode(p: &Pkg, out: &mut Vec<u8>) {
    let mut buf = [0u8; 1024];
    let n = match p {
        Pkg::Data(t, q, m) => {
            let s = RobotState {
                timestamp: *t,
                actual_q: *q,
                robot_mode: *m,
                ..Default::default()
            };
            s.encode_package(&recipe(), &mut buf).unwrap()
        }
        Pkg::Text(msg) => RobotMessage::TextMessage(TextMessage::V2 {
            message: msg,
            source: "prop",
            level: level::INFO,
        })
        .encode(&mut buf)
        .unwrap(),
        Pkg::Version(major) => RobotMessage::UrcontrolVersion(ControllerVersion {
            major: *major,
            ..Default::default()
        })
        .encode(&mut buf)
        .unwrap(),
        Pkg::Start(a) => RobotMessage::Start { accepted: *a }
            .encode(&mut buf)
            .unwrap(),
        Pkg::Setup(id) => RobotMessage::SetupOutputs {
            recipe_id: *id,
            types: RECIPE_TYPES,
        }
        .encode(&mut buf)
        .unwrap(),
    };
    out.extend_from_slice(&buf[..n]);
}

/// Decodes everything in `chunks` in order; returns a printable description of each package
/// (bit-exact for floats).
fn decode_chunks(chunks: &[&[u8]]) -> Vec<String> {
    let mut dec = FrameDecoder::<4096>::new();
    let recipe = recipe();
    let mut out = Vec::new();
    for chunk in chunks {
        let mut rest = *chunk;
        loop {
            let n = dec.push(rest);
            rest = &rest[n..];
            while let Some(f) = dec.next_frame().unwrap() {
                let m = RobotMessage::decode(&f, Protocol::V2).unwrap();
                let mut s = RobotState::default();
                if s.update(&recipe, &m).unwrap() {
                    out.push(format!(
                        "data {:x} {:?} {}",
                        s.timestamp.to_bits(),
                        s.actual_q.map(f64::to_bits),
                        s.robot_mode
                    ));
                } else {
                    out.push(format!("{m:?}"));
                }
            }
            if rest.is_empty() {
                break;
            }
        }
    }
    out
}

/// Cases per property: `FUZZ_CASES` (the long fuzz run of the README), else 2000.
fn cases() -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), ..ProptestConfig::default() })]

    #[test]
    fn any_split_or_merge_decodes_identically(
        pkgs in prop::collection::vec(pkg(), 1..20),
        cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..30),
    ) {
        let mut stream = Vec::new();
        for p in &pkgs {
            encode(p, &mut stream);
        }
        let whole = decode_chunks(&[&stream]);
        prop_assert_eq!(whole.len(), pkgs.len());
        let mut at: Vec<usize> = cuts.iter().map(|c| c.index(stream.len() + 1)).collect();
        at.push(0);
        at.push(stream.len());
        at.sort_unstable();
        let chunks: Vec<&[u8]> = at.windows(2).map(|w| &stream[w[0]..w[1]]).collect();
        prop_assert_eq!(decode_chunks(&chunks), whole);
        // One byte at a time.
        let bytes: Vec<&[u8]> = stream.chunks(1).collect();
        prop_assert_eq!(decode_chunks(&bytes), decode_chunks(&[&stream]));
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600), split in any::<prop::sample::Index>()) {
        let recipe = recipe();
        let mut dec = FrameDecoder::<256>::new();
        let cut = split.index(bytes.len() + 1);
        for chunk in [&bytes[..cut], &bytes[cut..]] {
            let mut rest = chunk;
            while !rest.is_empty() {
                let n = dec.push(rest);
                rest = &rest[n..];
                loop {
                    match dec.next_frame() {
                        Ok(Some(f)) => {
                            for p in [Protocol::V1, Protocol::V2] {
                                let _ = ClientMessage::decode(&f, p);
                                if let Ok(m) = RobotMessage::decode(&f, p) {
                                    let _ = RobotState::default().update(&recipe, &m);
                                }
                            }
                        }
                        Ok(None) => break,
                        Err(e) => {
                            prop_assert!(!e.to_string().is_empty());
                            dec.clear();
                            rest = &[];
                            break;
                        }
                    }
                }
                if n == 0 && !rest.is_empty() {
                    dec.clear();
                }
            }
        }
        // A payload decoded directly, whatever its type byte.
        if let Some(&t) = bytes.first() {
            if let Some(kind) = ur_protocol::PackageType::from_u8(t) {
                let f = Frame { kind, payload: &bytes[1..] };
                let _ = RobotMessage::decode(&f, Protocol::V2);
                let _ = ClientMessage::decode(&f, Protocol::V2);
            }
        }
        if bytes.len() >= 32 {
            let _ = ReverseCommand::decode(bytes[..32].try_into().unwrap());
        }
        let _ = ur_protocol::script::parse(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn state_round_trips_through_any_recipe(
        mask in prop::collection::vec(any::<bool>(), 43),
        t in -1e6f64..1e6, q in prop::array::uniform6(-7.0f64..7.0), mode in any::<i32>(), rt in any::<u32>(),
    ) {
        let names: Vec<&str> = ur_protocol::Output::fixed()
            .zip(&mask)
            .filter(|(_, m)| **m)
            .map(|(o, _)| o.base_name())
            .collect();
        let types: Vec<&str> = names
            .iter()
            .map(|n| ur_protocol::Output::from_name(n).unwrap().var_type().name())
            .collect();
        let recipe = OutputRecipe::from_answer(&names.join(","), 9, &types.join(",")).unwrap();
        let s = RobotState {
            timestamp: t, actual_q: q, target_q: q, actual_qd: q, robot_mode: mode,
            safety_mode: mode, runtime_state: rt, speed_scaling: t, joint_mode: [mode; 6],
            ..Default::default()
        };
        let mut buf = [0u8; 2048];
        let n = s.encode_package(&recipe, &mut buf).unwrap();
        let (f, len) = Frame::parse(&buf[..n], 4096).unwrap().unwrap();
        prop_assert_eq!(len, n);
        let m = RobotMessage::decode(&f, Protocol::V2).unwrap();
        let mut back = RobotState::default();
        prop_assert!(back.update(&recipe, &m).unwrap());
        let mut buf2 = [0u8; 2048];
        let n2 = back.encode_package(&recipe, &mut buf2).unwrap();
        prop_assert_eq!(&buf[..n], &buf2[..n2]);
    }
}
