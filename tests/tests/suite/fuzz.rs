//! Fuzzing on the stable toolchain: every decoder of outside bytes gets random and
//! mutated inputs from proptest, and must answer each with a value or a typed error — no panic,
//! no hang. Inputs are mutations of a valid file of the decoder's own kind (bytes flipped,
//! overwritten with boundary values, cut short, chunks duplicated or spliced in) and plain
//! random bytes.
//!
//! Cases per decoder: `FUZZ_CASES` (default 250, the whole suite ≈ 20 s in release); the long
//! run of the README is `FUZZ_CASES=100000 cargo test --release -p integration-tests --test
//! fuzz`. Each decoder prints `fuzz <name>: <cases> cases, <accepted> accepted, slowest <ms>`;
//! a case slower than [`SLOW`] fails the test as a hang.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

/// A single case slower than this counts as a hang.
const SLOW: Duration = Duration::from_secs(5);

fn cases() -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(250)
}

/// One mutation of a valid input.
#[derive(Clone, Debug)]
enum Edit {
    /// Byte at (fraction of the length) set to a value.
    Set(f64, u8),
    /// Eight bytes at a position overwritten with a boundary value (lengths, shapes, counts).
    Word(f64, u64),
    /// Cut at a fraction of the length.
    Cut(f64),
    /// A chunk (start, length as fractions) copied to a position.
    Splice(f64, f64, f64),
}

fn edit() -> impl Strategy<Value = Edit> {
    let boundary = prop_oneof![
        Just(0u64),
        Just(1),
        Just(u64::MAX),
        Just(u32::MAX as u64),
        Just(i64::MAX as u64),
        Just(0x7ff8_0000_0000_0000), // NaN
        Just(0x7ff0_0000_0000_0000), // inf
        any::<u64>(),
    ];
    prop_oneof![
        6 => (0.0..1.0f64, any::<u8>()).prop_map(|(a, b)| Edit::Set(a, b)),
        2 => (0.0..1.0f64, boundary).prop_map(|(a, w)| Edit::Word(a, w)),
        1 => (0.0..1.0f64).prop_map(Edit::Cut),
        1 => (0.0..1.0f64, 0.0..0.2f64, 0.0..1.0f64).prop_map(|(a, l, b)| Edit::Splice(a, l, b)),
    ]
}

fn apply(seed: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut v = seed.to_vec();
    let at = |f: f64, len: usize| ((f * len as f64) as usize).min(len.saturating_sub(1));
    for e in edits {
        if v.is_empty() {
            break;
        }
        match *e {
            Edit::Set(a, b) => {
                let i = at(a, v.len());
                v[i] = b;
            }
            Edit::Word(a, w) => {
                let i = at(a, v.len());
                let end = (i + 8).min(v.len());
                let n = end - i;
                // Little-endian (npy, zip) for even positions, big-endian (UR) for odd ones.
                let bytes = if i % 2 == 0 {
                    w.to_le_bytes()
                } else {
                    w.to_be_bytes()
                };
                v[i..end].copy_from_slice(&bytes[..n]);
            }
            Edit::Cut(a) => v.truncate(at(a, v.len())),
            Edit::Splice(a, l, b) => {
                let s = at(a, v.len());
                let e = (s + (l * v.len() as f64) as usize).min(v.len());
                let chunk = v[s..e].to_vec();
                let d = at(b, v.len());
                v.splice(d..d, chunk);
            }
        }
    }
    v
}

/// Random bytes (a fifth of the cases) or 1–8 mutations of `seed`.
fn inputs(seed: Vec<u8>) -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        1 => prop::collection::vec(any::<u8>(), 0..2048),
        4 => prop::collection::vec(edit(), 1..8).prop_map(move |e| apply(&seed, &e)),
    ]
}

/// Runs `decode` on [`cases`] inputs derived from `seed`; `decode` returns whether it accepted
/// the input. A panic or a case slower than [`SLOW`] fails the test with the (shrunk) input.
fn fuzz(name: &str, seed: Vec<u8>, decode: impl Fn(&[u8]) -> bool) {
    assert!(decode(&seed), "{name}: the valid seed input is refused");
    let n = cases();
    let mut runner = TestRunner::new(Config {
        cases: n,
        failure_persistence: None,
        max_shrink_iters: 2000,
        ..Config::default()
    });
    let accepted = std::cell::Cell::new(0u64);
    let slowest = std::cell::Cell::new(Duration::ZERO);
    let t0 = Instant::now();
    let result = runner.run(&inputs(seed), |bytes| {
        let t = Instant::now();
        let ok = decode(&bytes);
        let took = t.elapsed();
        accepted.set(accepted.get() + u64::from(ok));
        slowest.set(slowest.get().max(took));
        if took > SLOW {
            return Err(TestCaseError::fail(format!("took {took:?}: a hang")));
        }
        Ok(())
    });
    eprintln!(
        "fuzz {name}: {n} cases, {} accepted, slowest {:.1} ms, {:.1} s in all",
        accepted.get(),
        slowest.get().as_secs_f64() * 1e3,
        t0.elapsed().as_secs_f64()
    );
    if let Err(e) = result {
        panic!("fuzz {name}: {e}");
    }
}

/// Valid files of every kind, made once: a short expert's demonstrations (T = 30), one
/// LQR+GAIfO iteration's checkpoint (table, critic, learner state, CSV), an episode, the
/// expert checkpoint.
struct Seeds {
    dir: PathBuf,
    demos: imitation::demos::Demos,
}

fn seeds() -> &'static Seeds {
    static SEEDS: OnceLock<Seeds> = OnceLock::new();
    SEEDS.get_or_init(|| {
        use imitation::learn::Learn;
        let dir = std::env::temp_dir().join(format!("ur5-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ecfg = imitation::expert::ExpertConfig {
            task: ur5_shared::config::TaskConfig {
                horizon: 30,
                ..Default::default()
            },
            iterations: 3,
            random_episodes: 2,
            demos: 2,
            ..Default::default()
        };
        let run = learner::run::expert(&ecfg, |_| {}).unwrap();
        let demos = learner::run::demos(&ecfg, &run).unwrap();
        learner::io::demos::save(&demos, &dir.join("demos.npz")).unwrap();
        let cfg = imitation::gaifo::GaifoConfig {
            iterations: 1,
            ..Default::default()
        };
        learner::run::train(&cfg, demos.clone(), Some(&dir.join("run")), |_| {}).unwrap();
        let mut g = imitation::gaifo::LqrGaifo::new(cfg, demos.clone()).unwrap();
        let mut arm = learner::run::arm_for(&g).unwrap();
        let (noisy, _) = g.execute(&mut arm).unwrap();
        let origin = learner::io::episode::EpisodeOrigin {
            table_version: 1,
            table_epoch: 0,
            episode: 0,
            seed: 0,
        };
        learner::io::episode::save_episode(&dir.join("episode.npz"), &noisy[0], &origin, g.task())
            .unwrap();
        // A checkpoint with a best controller, so that its `best_*` arrays are fuzzed too.
        let c = learner::io::checkpoint::ExpertCheckpoint {
            pol: run.policy.clone(),
            iteration: 3,
            cost_random: Some(2.0),
            best: Some((run.policy.clone(), noisy[0].clone())),
            since_best: 1,
        };
        learner::io::checkpoint::save_checkpoint(&dir.join("checkpoint.npz"), &c, 1).unwrap();
        // One MDGPS iteration on the demonstrations' goal (its checkpoint), and its gain table
        // with an episode plan (goal and noise stream).
        let mcfg = mdgps_config();
        learner::run::train_mdgps(&mcfg, vec![demos.clone()], &dir.join("mdgps"), |_| {}).unwrap();
        let m = imitation::mdgps::Mdgps::new(mcfg, vec![demos.clone()]).unwrap();
        learner::io::table::save_table(&dir.join("planned_table.npz"), &m.gain_table(0, 1), 0.1)
            .unwrap();
        Seeds { dir, demos }
    })
}

/// The MDGPS settings of the seed run: one iteration, a small policy and S-step.
fn mdgps_config() -> imitation::mdgps::MdgpsConfig {
    let mut c = imitation::mdgps::MdgpsConfig::default();
    c.lqr_gaifo.iterations = 1;
    c.policy.hidden = vec![8];
    c.policy.steps = 20;
    c
}

fn seed_file(name: &str) -> Vec<u8> {
    std::fs::read(seeds().dir.join(name)).unwrap()
}

/// Decodes `bytes` as a file: written to a per-decoder scratch path, then read by `load`.
fn via_file<T, E>(tag: &str, load: impl Fn(&Path) -> Result<T, E>) -> impl Fn(&[u8]) -> bool {
    let path = seeds().dir.join(format!("case-{tag}"));
    move |bytes| {
        std::fs::write(&path, bytes).unwrap();
        load(&path).is_ok()
    }
}

#[test]
fn fuzz_demos_npz() {
    let sim = ur5_shared::config::SimConfig::default();
    fuzz(
        "demos.npz",
        seed_file("demos.npz"),
        via_file("demos.npz", |p| learner::io::demos::load_checked(p, &sim)),
    );
}

#[test]
fn fuzz_gain_table_npz() {
    let bounds = ur5_shared::GainBounds::default();
    fuzz(
        "table.npz",
        seed_file("run/iter_001_table.npz"),
        via_file("table.npz", |p| learner::io::table::load_table(p, &bounds)),
    );
}

#[test]
fn fuzz_episode_npz() {
    fuzz(
        "episode.npz",
        seed_file("episode.npz"),
        via_file("episode.npz", learner::io::episode::load_episode),
    );
}

#[test]
fn fuzz_expert_checkpoint_npz() {
    fuzz(
        "checkpoint.npz",
        seed_file("checkpoint.npz"),
        via_file("checkpoint.npz", learner::io::checkpoint::load_checkpoint),
    );
}

/// The learner state, read and then restored into a run of the seed's size.
#[test]
fn fuzz_learner_state_npz() {
    let s = seeds();
    let cfg = imitation::gaifo::GaifoConfig::default();
    let critic = s.dir.join("run/iter_001_critic.json");
    let disc = imitation::discriminator::Discriminator::load(&critic, 24).unwrap();
    fuzz(
        "state.npz",
        seed_file("run/iter_001_state.npz"),
        via_file("state.npz", |p| {
            let snap = learner::io::checkpoint::load_state(p).map_err(|e| e.to_string())?;
            imitation::gaifo::LqrGaifo::from_snapshot(
                cfg.clone(),
                s.demos.clone(),
                &snap,
                disc.clone(),
            )
            .map(|_| ())
            .map_err(|e| e.to_string())
        }),
    );
}

/// A gain table file with an episode plan (its `plan_*` arrays).
#[test]
fn fuzz_gain_table_with_a_plan_npz() {
    let bounds = ur5_shared::GainBounds::default();
    fuzz(
        "planned_table.npz",
        seed_file("planned_table.npz"),
        via_file("planned_table.npz", |p| {
            learner::io::table::load_table(p, &bounds)
        }),
    );
}

/// MDGPS's learner state, read and then restored into a run of the seed's size.
#[test]
fn fuzz_mdgps_state_npz() {
    let s = seeds();
    let critic = s.dir.join("mdgps/iter_001_critic.json");
    let disc = imitation::discriminator::Discriminator::load(&critic, 24).unwrap();
    fuzz(
        "mdgps state.npz",
        seed_file("mdgps/iter_001_state.npz"),
        via_file("mdgps-state.npz", |p| {
            let snap = learner::io::checkpoint::load_state(p).map_err(|e| e.to_string())?;
            imitation::mdgps::Mdgps::from_snapshot(
                mdgps_config(),
                vec![s.demos.clone()],
                &snap,
                disc.clone(),
            )
            .map(|_| ())
            .map_err(|e| e.to_string())
        }),
    );
}

#[test]
fn fuzz_critic_json() {
    fuzz(
        "critic.json",
        seed_file("run/iter_001_critic.json"),
        via_file("critic.json", |p| {
            imitation::discriminator::Discriminator::load(p, 24)
        }),
    );
}

/// The per-iteration CSV a resume reads (and rewrites) and the experiments' reader.
#[test]
fn fuzz_gaifo_csv() {
    fuzz(
        "gaifo_log.csv",
        seed_file("run/gaifo_log.csv"),
        via_file("gaifo_log.csv", |p| {
            let read = learner::io::log::read_gaifo_csv(p).is_ok();
            learner::io::log::open_log(p, Some(1)).map(|_| read)
        }),
    );
}

/// A TOML configuration of type `T`, parsed over the defaults and validated as its command
/// does.
fn fuzz_toml<T>(name: &str, validate: impl Fn(&T) -> bool)
where
    T: serde::Serialize + serde::de::DeserializeOwned + Default,
{
    let seed = toml::to_string(&T::default()).unwrap().into_bytes();
    fuzz(name, seed, |bytes| {
        let text = String::from_utf8_lossy(bytes);
        ur5_shared::config::from_toml_str::<T>(&text).is_ok_and(|c| validate(&c))
    });
}

#[test]
fn fuzz_toml_configs() {
    fuzz_toml::<imitation::gaifo::GaifoConfig>("train config", |c| c.validate().is_ok());
    fuzz_toml::<imitation::expert::ExpertConfig>("expert config", |c| c.validate().is_ok());
    fuzz_toml::<imitation::ppo::gaifo_ppo::GaifoPpoConfig>("gaifo-ppo config", |c| {
        c.validate().is_ok()
    });
    fuzz_toml::<rt_controller::config::ControllerConfig>("controller config", |c| {
        c.validate().is_ok()
    });
    fuzz_toml::<ur5_shared::config::SimConfig>("arm config", |c| {
        hil_sim::Ur5Sim::new(c.clone(), 0.05).is_ok()
    });
}

#[test]
fn fuzz_urdf() {
    let path = hil_sim::model::bundled_urdf_path();
    let seed = std::fs::read(&path).unwrap();
    let wrist_q = ur5_shared::config::SimConfig::default().wrist_q;
    fuzz("urdf", seed, |bytes| {
        let text = String::from_utf8_lossy(bytes);
        hil_sim::model::ArmModel::from_str(&text, path.clone(), wrist_q, "wrist_3_link", [0.0; 3])
            .is_ok()
    });
}

/// Reinterprets `bytes` (zero-padded or cut to size) as the plain-old-data payload `T`.
fn pod<T: Copy + Default>(bytes: &[u8]) -> T {
    let mut v = T::default();
    let n = bytes.len().min(std::mem::size_of::<T>());
    // SAFETY: only used with the repr(C) payloads of ur5_shared, made of integers and floats,
    // for which every bit pattern is a valid value.
    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), (&mut v as *mut T).cast::<u8>(), n) };
    v
}

fn bytes_of<T>(v: &T) -> Vec<u8> {
    // SAFETY: as in `pod`: repr(C) integers and floats, no padding bytes read uninitialised
    // (the payloads are padding-free, which ur5_shared's layout tests check).
    unsafe { std::slice::from_raw_parts((v as *const T).cast::<u8>(), std::mem::size_of::<T>()) }
        .to_vec()
}

/// The wire gain table as the controller takes it: validated, then evaluated at every step.
#[test]
fn fuzz_wire_gain_table() {
    let bounds = ur5_shared::GainBounds::default();
    let bytes_seed = {
        let (t, _) =
            learner::io::table::load_table(&seeds().dir.join("run/iter_001_table.npz"), &bounds)
                .unwrap();
        bytes_of(&*t)
    };
    let mut table = ur5_shared::GainTable::new_boxed();
    let table = std::cell::RefCell::new(&mut table);
    fuzz("wire GainTable", bytes_seed, |bytes| {
        let mut t = table.borrow_mut();
        let dst = &mut ***t as *mut ur5_shared::GainTable as *mut u8;
        let n = bytes
            .len()
            .min(std::mem::size_of::<ur5_shared::GainTable>());
        // SAFETY: GainTable is repr(C) of u64/u32/f64 only (see `pod`).
        unsafe {
            std::ptr::write_bytes(dst, 0, std::mem::size_of::<ur5_shared::GainTable>());
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), dst, n);
        }
        if t.validate(&bounds).is_err() {
            return false;
        }
        let mut a = [0.0; 3];
        (0..t.horizon() + 1).all(|k| {
            ur5_shared::controller_action(&t, k, &[0.1; 12], &[0.5; 3], &mut a).is_ok()
                || k == t.horizon()
        })
    });
}

/// IPC payloads as their receivers take them: samples into the learner's episode assembler,
/// commands into the arm (kind, finiteness, reset, step), states into the state vector.
#[test]
fn fuzz_ipc_payloads() {
    use ur5_shared::{ArmCommand, ArmState, StepSample};
    let seed_sample = StepSample {
        t: 3,
        episode: 1,
        table_version: 1,
        ..Default::default()
    };
    let one = std::mem::size_of::<StepSample>();
    let seed: Vec<u8> = (0..8).flat_map(|_| bytes_of(&seed_sample)).collect();
    fuzz("StepSample stream", seed, |bytes| {
        let mut asm = learner::serve::assemble::Assembler::new(30, ur5_shared::StateLayout::REACH3);
        for chunk in bytes.chunks(one) {
            let s: StepSample = pod(chunk);
            let _ = asm.push(&s);
        }
        true
    });
    let sim = std::cell::RefCell::new(
        hil_sim::Ur5Sim::new(ur5_shared::config::SimConfig::default(), 0.05).unwrap(),
    );
    let cmd = ArmCommand::goal_angles(1, 2, 3, [0.1, -0.5, 0.3]);
    fuzz("ArmCommand", bytes_of(&cmd), |bytes| {
        let c: ArmCommand = pod(bytes);
        let finite = c.values.iter().chain(&c.reset_pose).all(|v| v.is_finite());
        let mut sim = sim.borrow_mut();
        match c.kind() {
            Ok(ur5_shared::CommandKind::Reset) if finite => {
                let pose = core::array::from_fn(|j| c.reset_pose[j]);
                sim.reset(pose, [0.4, 0.1, 0.4]).is_ok()
            }
            Ok(ur5_shared::CommandKind::GoalAngles) if finite => {
                sim.step(core::array::from_fn(|j| c.values[j]));
                true
            }
            _ => false,
        }
    });
    let state = ArmState::default();
    fuzz("ArmState", bytes_of(&state), |bytes| {
        let s: ArmState = pod(bytes);
        s.state_vector(&[0.4, 0.1, 0.4])
            .iter()
            .all(|v| v.is_finite())
    });
}

/// The UR protocol: a mutated valid RTDE stream through the frame decoder, every package
/// decoded for both protocol versions and applied to a robot state; reverse commands; the
/// program header; recipe answers.
#[test]
fn fuzz_ur_protocol() {
    use ur_protocol::recipe::OutputRecipe;
    use ur_protocol::rtde::{level, Protocol, TextMessage};
    use ur_protocol::stream::FrameDecoder;
    use ur_protocol::{ClientMessage, ReverseCommand, RobotMessage, RobotState};
    const NAMES: &str = "timestamp,actual_q,actual_qd,robot_mode,safety_mode,runtime_state";
    const TYPES: &str = "DOUBLE,VECTOR6D,VECTOR6D,INT32,INT32,UINT32";
    let recipe = OutputRecipe::from_answer(NAMES, 1, TYPES).unwrap();
    let mut seed = Vec::new();
    let mut buf = [0u8; 1024];
    let state = RobotState {
        timestamp: 1.5,
        actual_q: [0.1; 6],
        robot_mode: 7,
        ..Default::default()
    };
    let n = state.encode_package(&recipe, &mut buf).unwrap();
    seed.extend_from_slice(&buf[..n]);
    let text = RobotMessage::TextMessage(TextMessage::V2 {
        message: "hello",
        source: "fuzz",
        level: level::INFO,
    });
    let n = text.encode(&mut buf).unwrap();
    seed.extend_from_slice(&buf[..n]);
    let n = RobotMessage::SetupOutputs {
        recipe_id: 1,
        types: TYPES,
    }
    .encode(&mut buf)
    .unwrap();
    seed.extend_from_slice(&buf[..n]);
    let reverse = ReverseCommand {
        timeout_ms: 20,
        q: [0.1; 6],
        mode: ur_protocol::ControlMode::Servoj,
    };
    seed.extend_from_slice(&reverse.encode().unwrap());
    fuzz("RTDE stream and UR packages", seed, |bytes| {
        let mut dec = FrameDecoder::<512>::new();
        let mut rest = bytes;
        let mut frames = 0;
        let mut s = RobotState::default();
        while !rest.is_empty() {
            let n = dec.push(rest);
            rest = &rest[n..];
            loop {
                match dec.next_frame() {
                    Ok(Some(f)) => {
                        frames += 1;
                        for p in [Protocol::V1, Protocol::V2] {
                            let _ = ClientMessage::decode(&f, p);
                            if let Ok(m) = RobotMessage::decode(&f, p) {
                                let _ = s.update(&recipe, &m);
                                if let RobotMessage::SetupOutputs { recipe_id, types } = m {
                                    let _ = OutputRecipe::from_answer(NAMES, recipe_id, types);
                                }
                            }
                        }
                    }
                    Ok(None) => break,
                    Err(_) => {
                        dec.clear();
                        break;
                    }
                }
            }
            if n == 0 && !rest.is_empty() {
                dec.clear();
                rest = &rest[1..];
            }
        }
        for w in bytes.windows(32).step_by(16) {
            let _ = ReverseCommand::decode(w.try_into().unwrap());
        }
        let _ = ur_protocol::script::parse(&String::from_utf8_lossy(bytes));
        frames > 0
    });
}
