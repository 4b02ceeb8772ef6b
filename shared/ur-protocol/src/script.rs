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
/// `# params: reverse=127.0.0.1:50001 steptime=0.002`.
pub const PARAMS_PREFIX: &str = "# params: ";

/// Placeholder for the PC's address as the robot sees it (dotted IPv4).
pub const PH_REVERSE_IP: &str = "{{REVERSE_IP}}";
/// Placeholder for the reverse port.
pub const PH_REVERSE_PORT: &str = "{{REVERSE_PORT}}";
/// Placeholder for the arm cycle (s): 0.002 (e-Series) or 0.008 (CB3).
pub const PH_STEPTIME: &str = "{{STEPTIME}}";

/// What the driver fills in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScriptParams {
    /// The PC's IPv4 address as the robot reaches it.
    pub reverse_ip: std::net::Ipv4Addr,
    /// The PC's reverse port.
    pub reverse_port: u16,
    /// Arm cycle (s): servoj's `t`.
    pub steptime_s: f64,
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
}

/// Reads the parameters back from a rendered program.
pub fn parse(script: &str) -> Result<ScriptParams, ScriptError> {
    if !script.lines().any(|l| l.trim() == MARKER) {
        return Err(ScriptError::NotOurs);
    }
    for ph in [PH_REVERSE_IP, PH_REVERSE_PORT, PH_STEPTIME] {
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
    for kv in line.split_whitespace() {
        match kv.split_once('=') {
            Some(("reverse", v)) => reverse = Some(v),
            Some(("steptime", v)) => steptime = Some(v),
            _ => {}
        }
    }
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
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEMPLATE: &str = "def p():\n  # ur5-lqr-gaifo external_control v1\n  # params: reverse={{REVERSE_IP}}:{{REVERSE_PORT}} steptime={{STEPTIME}}\n  socket_open(\"{{REVERSE_IP}}\", {{REVERSE_PORT}}, \"reverse_socket\")\nend\n";

    #[test]
    fn render_then_parse() {
        let p = ScriptParams {
            reverse_ip: "127.0.0.1".parse().unwrap(),
            reverse_port: 50001,
            steptime_s: 0.002,
        };
        let s = render(TEMPLATE, &p);
        assert!(s.contains("socket_open(\"127.0.0.1\", 50001,"));
        assert_eq!(parse(&s).unwrap(), p);
        assert_eq!(parse(TEMPLATE), Err(ScriptError::Unrendered(PH_REVERSE_IP)));
        assert_eq!(parse("movej([0,0,0,0,0,0])\n"), Err(ScriptError::NotOurs));
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
        for ph in [PH_REVERSE_IP, PH_REVERSE_PORT, PH_STEPTIME] {
            assert!(template.contains(ph), "{ph}");
        }
        let p = ScriptParams {
            reverse_ip: "127.0.0.1".parse().unwrap(),
            reverse_port: 50001,
            steptime_s: 0.008,
        };
        let s = render(template, &p);
        assert_eq!(parse(&s).unwrap(), p);
        assert!(s.contains("servoj(target, t=0.008,"));
    }
}
