//! The project's robot-side URScript program (`rt-controller/urscript/external_control.script`):
//! its marker, its placeholders, and reading them back from a rendered program.
//!
//! The driver sends the rendered program as text to the secondary interface (TCP 30002); a
//! controller runs it at once. The program's header holds a marker line ([`MARKER`]) and a
//! parameter line ([`PARAMS_PREFIX`]) so that `hil-sim ur-sim` can recognise the program and
//! act as it would: connect to the reverse port, servo to the targets, stop on a timeout.

/// The line that identifies this project's program (a URScript comment).
pub const MARKER: &str = "# ur5-lqr-gaifo external_control v1";

/// Start of the header line that carries the parameters, e.g.
/// `# params: reverse=127.0.0.1:50001 steptime=0.002 lookahead=0.1 gain=300` (`lookahead` and
/// `gain` may be missing: a program from before they were settings, servoj's 0.1 s and 300).
pub const PARAMS_PREFIX: &str = "# params: ";

/// Placeholder for the PC's address as the robot sees it (dotted IPv4).
pub const PH_REVERSE_IP: &str = "{{REVERSE_IP}}";
/// Placeholder for the reverse port.
pub const PH_REVERSE_PORT: &str = "{{REVERSE_PORT}}";
/// Placeholder for the arm cycle (s): 0.002 (e-Series) or 0.008 (CB3).
pub const PH_STEPTIME: &str = "{{STEPTIME}}";
/// Placeholder for servoj's `lookahead_time` (s, 0.03–0.2).
pub const PH_LOOKAHEAD: &str = "{{LOOKAHEAD_TIME}}";
/// Placeholder for servoj's `gain` (100–2000).
pub const PH_GAIN: &str = "{{GAIN}}";

/// servoj's `lookahead_time` of a program whose parameter line does not name it (s).
pub const DEFAULT_LOOKAHEAD_S: f64 = 0.1;
/// servoj's `gain` of a program whose parameter line does not name it.
pub const DEFAULT_GAIN: f64 = 300.0;
/// `lookahead_time` as URScript accepts it (s).
pub const LOOKAHEAD_RANGE_S: (f64, f64) = (0.03, 0.2);
/// `gain` as URScript accepts it.
pub const GAIN_RANGE: (f64, f64) = (100.0, 2000.0);

const PLACEHOLDERS: [&str; 5] = [
    PH_REVERSE_IP,
    PH_REVERSE_PORT,
    PH_STEPTIME,
    PH_LOOKAHEAD,
    PH_GAIN,
];

/// What the driver fills in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScriptParams {
    /// The PC's IPv4 address as the robot reaches it.
    pub reverse_ip: std::net::Ipv4Addr,
    /// The PC's reverse port.
    pub reverse_port: u16,
    /// Arm cycle (s): servoj's `t`.
    pub steptime_s: f64,
    /// servoj's `lookahead_time` (s, 0.03–0.2).
    pub lookahead_time_s: f64,
    /// servoj's `gain` (100–2000).
    pub gain: f64,
}

impl ScriptParams {
    /// The parameters with servoj's default `lookahead_time` and `gain`.
    pub fn new(reverse_ip: std::net::Ipv4Addr, reverse_port: u16, steptime_s: f64) -> Self {
        Self {
            reverse_ip,
            reverse_port,
            steptime_s,
            lookahead_time_s: DEFAULT_LOOKAHEAD_S,
            gain: DEFAULT_GAIN,
        }
    }
}

/// Why a program is not this project's, or is malformed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ScriptError {
    /// No marker line.
    #[error("not this project's external_control program (no `{MARKER}` line)")]
    NotOurs,
    /// The marker is there but the parameter line is missing or malformed.
    #[error("external_control program: bad `{PARAMS_PREFIX}` line: {0}")]
    BadParams(&'static str),
    /// Placeholders left unsubstituted.
    #[error("external_control program still contains the placeholder {0}; render it first")]
    Unrendered(&'static str),
}

/// Substitutes the placeholders of `template` (setup only: allocates the text).
pub fn render(template: &str, p: &ScriptParams) -> String {
    template
        .replace(PH_REVERSE_IP, &p.reverse_ip.to_string())
        .replace(PH_REVERSE_PORT, &p.reverse_port.to_string())
        .replace(PH_STEPTIME, &format!("{}", p.steptime_s))
        .replace(PH_LOOKAHEAD, &format!("{}", p.lookahead_time_s))
        .replace(PH_GAIN, &format!("{}", p.gain))
}

/// Reads the parameters back from a rendered program.
pub fn parse(script: &str) -> Result<ScriptParams, ScriptError> {
    if !script.lines().any(|l| l.trim() == MARKER) {
        return Err(ScriptError::NotOurs);
    }
    for ph in PLACEHOLDERS {
        if script.contains(ph) {
            return Err(ScriptError::Unrendered(ph));
        }
    }
    let line = script
        .lines()
        .find_map(|l| l.trim().strip_prefix(PARAMS_PREFIX))
        .ok_or(ScriptError::BadParams("missing"))?;
    let mut reverse = None;
    let mut steptime = None;
    let mut lookahead = None;
    let mut gain = None;
    for kv in line.split_whitespace() {
        match kv.split_once('=') {
            Some(("reverse", v)) => reverse = Some(v),
            Some(("steptime", v)) => steptime = Some(v),
            Some(("lookahead", v)) => lookahead = Some(v),
            Some(("gain", v)) => gain = Some(v),
            _ => {}
        }
    }
    let in_range = |v: Option<&str>, default: f64, (lo, hi): (f64, f64)| match v {
        None => Some(default),
        Some(v) => v.parse().ok().filter(|x: &f64| *x >= lo && *x <= hi),
    };
    let lookahead_time_s = in_range(lookahead, DEFAULT_LOOKAHEAD_S, LOOKAHEAD_RANGE_S).ok_or(
        ScriptError::BadParams("lookahead=SECONDS not in [0.03, 0.2]"),
    )?;
    let gain = in_range(gain, DEFAULT_GAIN, GAIN_RANGE)
        .ok_or(ScriptError::BadParams("gain= not in [100, 2000]"))?;
    let (ip, port) = reverse
        .and_then(|r| r.rsplit_once(':'))
        .ok_or(ScriptError::BadParams("no reverse=IP:PORT"))?;
    let steptime_s: f64 = steptime
        .and_then(|s| s.parse().ok())
        .filter(|s: &f64| s.is_finite() && *s > 0.0 && *s <= 0.1)
        .ok_or(ScriptError::BadParams("no steptime=SECONDS in (0, 0.1]"))?;
    Ok(ScriptParams {
        reverse_ip: ip
            .parse()
            .map_err(|_| ScriptError::BadParams("reverse IP is not IPv4"))?,
        reverse_port: port
            .parse()
            .map_err(|_| ScriptError::BadParams("reverse port is not a u16"))?,
        steptime_s,
        lookahead_time_s,
        gain,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEMPLATE: &str = "def p():\n  # ur5-lqr-gaifo external_control v1\n  # params: reverse={{REVERSE_IP}}:{{REVERSE_PORT}} steptime={{STEPTIME}} lookahead={{LOOKAHEAD_TIME}} gain={{GAIN}}\n  socket_open(\"{{REVERSE_IP}}\", {{REVERSE_PORT}}, \"reverse_socket\")\nend\n";

    #[test]
    fn render_then_parse() {
        let p = ScriptParams {
            reverse_ip: "127.0.0.1".parse().unwrap(),
            reverse_port: 50001,
            steptime_s: 0.002,
            lookahead_time_s: 0.05,
            gain: 1200.0,
        };
        let s = render(TEMPLATE, &p);
        assert!(s.contains("socket_open(\"127.0.0.1\", 50001,"));
        assert_eq!(parse(&s).unwrap(), p);
        assert_eq!(parse(TEMPLATE), Err(ScriptError::Unrendered(PH_REVERSE_IP)));
        assert_eq!(parse("movej([0,0,0,0,0,0])\n"), Err(ScriptError::NotOurs));
        // A program from before lookahead and gain were settings: servoj's old constants.
        let old =
            "# ur5-lqr-gaifo external_control v1\n# params: reverse=127.0.0.1:1 steptime=0.008\n";
        let q = parse(old).unwrap();
        assert_eq!((q.lookahead_time_s, q.gain), (0.1, 300.0));
        for bad in [
            "lookahead=0.01",
            "lookahead=0.3",
            "gain=50",
            "gain=3000",
            "gain=x",
        ] {
            let t = format!("# ur5-lqr-gaifo external_control v1\n# params: reverse=127.0.0.1:1 steptime=0.008 {bad}\n");
            assert!(matches!(parse(&t), Err(ScriptError::BadParams(_))), "{bad}");
        }
    }
}

#[cfg(test)]
mod shipped {
    use super::*;

    /// The program shipped in the repository has the marker, the parameter line and every
    /// placeholder, and renders to a program `parse` reads back.
    #[test]
    fn shipped_program_renders_and_parses() {
        let template = include_str!("../../../rt-controller/urscript/external_control.script");
        assert!(template.contains(MARKER));
        for ph in PLACEHOLDERS {
            assert!(template.contains(ph), "{ph}");
        }
        let p = ScriptParams {
            reverse_ip: "127.0.0.1".parse().unwrap(),
            reverse_port: 50001,
            steptime_s: 0.008,
            lookahead_time_s: 0.1,
            gain: 300.0,
        };
        let s = render(template, &p);
        assert_eq!(parse(&s).unwrap(), p);
        assert!(
            s.contains("servoj(target, t=0.008, lookahead_time=0.1, gain=300)"),
            "{s}"
        );
    }
}
