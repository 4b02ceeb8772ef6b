//! `learner plot arm` (docs/design.md §4.8): the filmstrip PNG and the animated GIF
//! of a tiny run are produced and decode.

use crate::common;

use imitation::gaifo::GaifoConfig;

#[test]
fn filmstrip_png_and_gif_of_a_run_are_produced_and_decode() {
    let dir = std::env::temp_dir().join(format!("learner-pictures-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ecfg = common::short_expert(20, 3);
    let s = learner::run::train_and_record(&ecfg, &dir.join("expert"), |_| {}).unwrap();
    let demos = learner::io::demos::load(&s.demos).unwrap();
    let cfg = GaifoConfig {
        iterations: 2,
        ..GaifoConfig::default()
    };
    learner::run::train(&cfg, demos, Some(&dir), |_| {}).unwrap();
    let (motions, goal, dt) = learner::film::run_motions(&dir, &s.demos, 3).unwrap();
    let labels: Vec<&str> = motions.iter().map(|m| m.label.as_str()).collect();
    assert_eq!(
        labels,
        [
            "expert",
            "imitator, 0 iterations",
            "imitator, 1 iterations",
            "imitator, 2 iterations"
        ]
    );
    assert!(motions.iter().all(|m| m.chain.len() == 20));
    // The expert's end effector ends nearer the goal than the untrained controller's.
    let end = |i: usize| {
        let p = motions[i].chain[19][7];
        (0..3).map(|k| (p[k] - goal[k]).powi(2)).sum::<f64>().sqrt()
    };
    assert!(
        end(0) < end(1),
        "expert {} m, iteration 0 {} m",
        end(0),
        end(1)
    );

    let png = dir.join("arm_filmstrip.png");
    let gif = dir.join("arm.gif");
    learner::film::filmstrip(&png, &motions, &goal, dt, 4).unwrap();
    learner::film::animation(&gif, &motions, &goal, dt, 5).unwrap();

    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (4 * 240, 480));
    assert!(buf.iter().any(|&b| b < 128), "something drawn");

    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    let mut d = opts.read_info(std::fs::File::open(&gif).unwrap()).unwrap();
    assert_eq!((d.width(), d.height()), (640, 320));
    let mut frames = 0;
    while let Some(f) = d.read_next_frame().unwrap() {
        assert!(
            f.buffer.chunks(4).any(|p| p[0] < 128),
            "frame {frames} drawn"
        );
        frames += 1;
    }
    assert_eq!(frames, 4 + 1, "steps 0, 5, 10, 15 and the last");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn plot_arm_draws_the_demonstrations_the_run_names() {
    // A run trained on demonstrations outside its folder: `plot arm RUN` finds them through
    // run.json (it looked for RUN/expert/demos.npz only), and refuses other ones.
    let dir = std::env::temp_dir().join(format!("learner-plot-demos-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let demos = dir.join("mine").join("demos.npz");
    std::fs::create_dir_all(demos.parent().unwrap()).unwrap();
    common::save_short_demos(&demos, 5);
    let run = dir.join("run");
    let (ok, err) = common::learner(&[
        "train",
        "--demos",
        demos.to_str().unwrap(),
        "--iterations",
        "1",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(!run.join("expert").join("demos.npz").exists());
    let (ok, err) = common::learner(&["plot", "arm", run.to_str().unwrap(), "--frames", "2"]);
    assert!(ok, "{err}");
    assert!(err.contains("expert, imitator, 0 iterations"), "{err}");
    assert!(run.join("arm_filmstrip.png").is_file() && run.join("arm.gif").is_file());
    // Other demonstrations are not the run's: named, not drawn.
    let other = dir.join("other.npz");
    common::save_short_demos(&other, 6);
    let (ok, err) = common::learner(&[
        "plot",
        "arm",
        run.to_str().unwrap(),
        "--demos",
        other.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("not the run's demonstrations"), "{err}");
    // Moved demonstrations: the error says where the run's were and how to pass them.
    std::fs::rename(&demos, dir.join("moved.npz")).unwrap();
    let (ok, err) = common::learner(&["plot", "arm", run.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        err.contains("demos.npz") && err.contains("--demos"),
        "{err}"
    );
    let (ok, err) = common::learner(&[
        "plot",
        "arm",
        run.to_str().unwrap(),
        "--demos",
        dir.join("moved.npz").to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
