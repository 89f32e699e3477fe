//! Recorded sessions: parsing, clear errors naming line and column, replay
//! and bit-identical write/read round trips.

use surgbench_core::haptic::{Feedback, HapticDevice, ReplayDevice, ScriptedDevice, Session};
use surgbench_core::{ControlKey, ControlTimeline, Vec3};

const TEXT: &str = "# recorded at 10 Hz\nt, insertion, rotation\n0,0,0\n0.1,0.001,0\n0.2,0.002,0.3\n0.3,0.003,0.6\n0.4,0.004,0.6\n0.5,0.004,0.2\n";

#[test]
fn parses_plays_and_counts_rotation_commands() {
    let s = Session::parse("s.csv", TEXT).unwrap();
    assert_eq!(s.timeline.keys.len(), 6);
    assert_eq!(s.duration(), 0.5);
    // 0 -> 0.3 -> 0.6 is one move, 0.6 -> 0.2 another.
    assert_eq!(s.rotation_commands(), 2);
    let mut dev = ReplayDevice::new(s.clone());
    let c = dev.command(0.25);
    assert!(
        (c.insertion - 0.0025).abs() < 1e-15 && (c.rotation - 0.45).abs() < 1e-15,
        "{c:?}"
    );
    // Past the end the last sample holds.
    assert_eq!(dev.command(9.0).insertion, 0.004);
    // Columns in another order, extra columns ignored.
    let t = Session::parse("s.csv", "rotation,fx,t,insertion\n0,1,0,0\n0.5,2,1,0.01\n").unwrap();
    assert_eq!(t.timeline.keys[1], ControlKey::feed(1.0, 0.01, 0.5));
}

#[test]
fn errors_name_line_and_column() {
    let e = Session::parse("s.csv", "t,insertion\n0,0\n").unwrap_err();
    assert_eq!((e.line, e.column.as_str()), (1, "rotation"), "{e}");
    assert!(e.to_string().contains("no `rotation` column"), "{e}");
    let e = Session::parse("s.csv", "t,insertion,rotation\n0,0,0\n0.1,abc,0\n").unwrap_err();
    assert_eq!((e.line, e.column.as_str()), (3, "insertion"), "{e}");
    assert_eq!(
        e.to_string(),
        "s.csv: line 3, column `insertion`: `abc` is not a finite number"
    );
    let e = Session::parse("s.csv", "t,insertion,rotation\n0,0,0\n0,0,1\n").unwrap_err();
    assert!(
        e.to_string().contains("line 3") && e.to_string().contains("does not increase"),
        "{e}"
    );
    let e = Session::parse("s.csv", "t,insertion,rotation\n0,0\n").unwrap_err();
    assert!(e.to_string().contains("2 fields"), "{e}");
    assert!(Session::parse("s.csv", "").unwrap_err().to_string().contains("empty"));
    assert!(
        Session::parse("s.csv", "t,insertion,rotation\n")
            .unwrap_err()
            .to_string()
            .contains("no samples")
    );
    let e = Session::load(std::path::Path::new("/nonexistent/session.csv")).unwrap_err();
    assert!(e.to_string().starts_with("/nonexistent/session.csv"), "{e}");
}

#[test]
fn recording_round_trips_bit_identically() {
    let s = Session::parse("s.csv", TEXT).unwrap();
    let mut dev = ReplayDevice::new(s);
    for k in 0..=700 {
        let t = k as f64 * 1e-3;
        let c = dev.command(t);
        // A feedback that depends on the command, with awkward decimals.
        dev.render(&Feedback {
            t,
            force: Vec3::new(c.insertion * 1.1, -0.1 / 3.0, c.rotation.sin()),
            torque: Vec3::new(c.rotation * 1e-3, 0.0, 1.0 / 7.0),
        });
    }
    let csv = dev.to_csv();
    let again = Session::parse("rec.csv", &csv).unwrap();
    assert_eq!(again.timeline.keys.len(), 701);
    for (k, (c, f)) in again.timeline.keys.iter().zip(dev.rendered()) {
        assert_eq!(k.t.to_bits(), f.t.to_bits());
        assert_eq!(k.insertion.to_bits(), c.insertion.to_bits());
        assert_eq!(k.rotation.to_bits(), c.rotation.to_bits());
    }
    // Replaying the recording gives the same command stream, bit for bit.
    let mut dev2 = ReplayDevice::new(again);
    for (c, f) in dev.rendered() {
        assert_eq!(dev2.command(f.t), *c, "t={}", f.t);
    }
}

#[test]
fn scripted_device_plays_its_timeline() {
    let tl = ControlTimeline {
        keys: vec![ControlKey::feed(0.0, 0.0, 0.0), ControlKey::feed(2.0, 0.04, 1.0)],
    };
    let mut d = ScriptedDevice::new(tl.clone());
    assert_eq!(d.command(1.0), tl.command_at(1.0));
    let f = Feedback {
        t: 1.0,
        force: Vec3::x(),
        torque: Vec3::zeros(),
    };
    d.render(&f);
    assert_eq!(d.last, Some(f));
    let mut none = ();
    assert_eq!(none.command(3.0), Default::default());
}
