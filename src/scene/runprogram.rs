//! The programs behind `Procedural "RunProgram"` (RISpec 3.2 §5.8, PRMan's protocol).
//!
//! Input: a command line (program and arguments), the path the program was found at, and one
//! request line `"detail datablock\n"` per procedural. Output: the RIB bytes the program wrote
//! for that request, up to (not including) the byte `\377` that ends each reply.
//! Invariants: one process per distinct command line, started on its first request and kept
//! running for the next ones (the program loops reading requests from its standard input);
//! the builder never blocks on the program: writes go through a writer thread, reads come
//! from a reader thread with an inactivity timeout, after which the process is killed. A
//! program that failed (could not start, exited, timed out, wrote too much) is not started
//! again. At the end of the build every program's standard input is closed so it exits; one
//! that does not within [`EXIT_GRACE`] is killed.

use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The byte that ends each reply.
pub const END_OF_REPLY: u8 = 0xFF;
/// The longest reply kept (a program that writes without end is stopped there).
pub const MAX_REPLY: usize = 1 << 31;
/// How long a program may take to exit once its standard input is closed.
pub const EXIT_GRACE: Duration = Duration::from_secs(2);
/// How much of a program's standard error is kept (its last bytes).
const STDERR_KEEP: usize = 16 * 1024;

/// Why a request got no reply.
#[derive(Clone, Debug, PartialEq)]
pub struct ProgramError {
    pub message: String,
    pub help: String,
    /// False when the program had already failed on an earlier request (this one was not
    /// sent).
    pub first: bool,
}

enum Chunk {
    Data(Vec<u8>),
    End(Option<std::io::Error>),
}

struct Proc {
    child: Child,
    /// Request lines to the writer thread; dropping it closes the program's standard input.
    to_child: Option<Sender<Vec<u8>>>,
    from_child: Receiver<Chunk>,
    /// Bytes read but not yet part of a reply.
    pending: Vec<u8>,
    stderr: Arc<Mutex<Vec<u8>>>,
    /// Signalled when the stderr reader has seen the end of the program's standard error.
    stderr_done: Receiver<()>,
    /// Set once the program has failed; later requests are refused with it.
    failed: Option<String>,
}

/// The running programs of one build, keyed by command line.
#[derive(Default)]
pub struct Programs {
    procs: HashMap<String, Proc>,
}

impl Programs {
    /// Sends `line` to the program `command` (started from `exe` with `args` if it is not
    /// running yet) and waits for its reply.
    pub fn request(
        &mut self,
        command: &str,
        exe: &Path,
        args: &[String],
        line: &[u8],
        timeout: Duration,
    ) -> Result<Vec<u8>, ProgramError> {
        if !self.procs.contains_key(command) {
            let p = start(exe, args).map_err(|e| ProgramError {
                message: format!("cannot start `{}`: {e}", exe.display()),
                help: "check that the program exists and is executable (a script needs a `#!` line and the execute bit)".into(),
                first: true,
            })?;
            self.procs.insert(command.to_string(), p);
        }
        let Some(p) = self.procs.get_mut(command) else {
            return Err(ProgramError {
                message: "internal: program table".into(),
                help: String::new(),
                first: true,
            });
        };
        if let Some(f) = &p.failed {
            return Err(ProgramError {
                message: format!("`{command}` failed earlier ({f}); not run again"),
                help: "fix the program; procedurals after its first failure are skipped".into(),
                first: false,
            });
        }
        let result = p.exchange(line, timeout);
        if let Err(e) = &result {
            p.failed = Some(short(&e.message));
            p.kill();
        }
        result
    }

    /// Closes every program's input and waits for it to exit (killing it after
    /// [`EXIT_GRACE`]). Returns, per program that did not end cleanly or wrote to its
    /// standard error, the command and a message.
    pub fn close_all(&mut self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        let mut procs: Vec<(String, Proc)> = self.procs.drain().collect();
        procs.sort_by(|a, b| a.0.cmp(&b.0));
        for (_, p) in procs.iter_mut() {
            p.to_child = None;
        }
        for (cmd, mut p) in procs {
            let already_failed = p.failed.is_some();
            let status = wait_with_grace(&mut p.child, EXIT_GRACE);
            let stderr = p.stderr_tail();
            if already_failed {
                continue;
            }
            let mut msg = String::new();
            match status {
                Some(s) if s.success() => {}
                Some(s) => msg = format!("exited with {s} at the end of the frame"),
                None => {
                    msg = format!(
                        "did not exit within {} s of its input closing; killed",
                        EXIT_GRACE.as_secs()
                    )
                }
            }
            if !stderr.is_empty() {
                if !msg.is_empty() {
                    msg.push_str("; ");
                }
                msg.push_str(&format!("its standard error ended with:\n{stderr}"));
            }
            if !msg.is_empty() {
                out.push((cmd, msg));
            }
        }
        out
    }
}

impl Drop for Programs {
    fn drop(&mut self) {
        for (_, mut p) in self.procs.drain() {
            p.to_child = None;
            if wait_with_grace(&mut p.child, Duration::from_millis(200)).is_none() {
                p.kill();
            }
        }
    }
}

impl Proc {
    fn exchange(&mut self, line: &[u8], timeout: Duration) -> Result<Vec<u8>, ProgramError> {
        let sent = self
            .to_child
            .as_ref()
            .is_some_and(|tx| tx.send(line.to_vec()).is_ok());
        if !sent {
            return Err(self.ended("closed its input before the request was sent", 0));
        }
        let mut scanned = 0;
        loop {
            if let Some(i) = self.pending[scanned..]
                .iter()
                .position(|&b| b == END_OF_REPLY)
            {
                let end = scanned + i;
                let mut reply: Vec<u8> = self.pending.drain(..=end).collect();
                reply.pop();
                return Ok(reply);
            }
            scanned = self.pending.len();
            if self.pending.len() > MAX_REPLY {
                return Err(ProgramError {
                    message: format!(
                        "wrote more than {} MiB without ending its reply with the byte \\377",
                        MAX_REPLY >> 20
                    ),
                    help: "end each reply with the byte 0377 (printf '\\377'; in Python sys.stdout.write('\\xff') on a binary stream)".into(),
                    first: true,
                });
            }
            match self.from_child.recv_timeout(timeout) {
                Ok(Chunk::Data(d)) => self.pending.extend_from_slice(&d),
                Ok(Chunk::End(err)) => {
                    let what = match err {
                        Some(e) => format!("its output failed ({e})"),
                        None => "closed its output".into(),
                    };
                    let n = self.pending.len();
                    return Err(self.ended(&what, n));
                }
                Err(RecvTimeoutError::Disconnected) => {
                    let n = self.pending.len();
                    return Err(self.ended("closed its output", n));
                }
                Err(RecvTimeoutError::Timeout) => {
                    return Err(ProgramError {
                        message: format!(
                            "wrote nothing for {:.3} s without ending its reply; killed",
                            timeout.as_secs_f64()
                        ),
                        help: format!(
                            "a RunProgram program reads \"detail datablock\" lines and answers each with RIB followed by the byte \\377{}; a slow program can be given more time with --program-timeout",
                            self.stderr_note()
                        ),
                        first: true,
                    });
                }
            }
        }
    }

    /// The error for a program whose output ended before its reply did.
    fn ended(&mut self, what: &str, bytes: usize) -> ProgramError {
        let status = wait_with_grace(&mut self.child, Duration::from_millis(500));
        // The program has exited: let the stderr reader drain what it wrote last, so the
        // message can quote it (a short wait; a grandchild may still hold the pipe).
        let _ = self.stderr_done.recv_timeout(Duration::from_millis(500));
        let status = match status {
            Some(s) => format!(" ({s})"),
            None => String::new(),
        };
        let partial = if bytes > 0 {
            format!(" ({bytes} bytes of RIB dropped)")
        } else {
            String::new()
        };
        ProgramError {
            message: format!(
                "{what}{status} before ending its reply with the byte \\377{partial}"
            ),
            help: format!(
                "the program must keep running, reading one \"detail datablock\" line per procedural and writing RIB followed by the byte \\377 (printf '\\377'){}",
                self.stderr_note()
            ),
            first: true,
        }
    }

    fn stderr_tail(&self) -> String {
        let e = self.stderr.lock().unwrap_or_else(|e| e.into_inner());
        String::from_utf8_lossy(&e).trim_end().to_string()
    }

    fn stderr_note(&self) -> String {
        let t = self.stderr_tail();
        if t.is_empty() {
            String::new()
        } else {
            let lines: Vec<&str> = t.lines().collect();
            let last = lines[lines.len().saturating_sub(5)..].join("\n  ");
            format!("; its standard error ended with:\n  {last}")
        }
    }

    fn kill(&mut self) {
        self.to_child = None;
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// Waits up to `grace` for the child to exit; kills it after that (returning None).
fn wait_with_grace(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    let start = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(s)) => return Some(s),
            Ok(None) if start.elapsed() < grace => std::thread::sleep(Duration::from_millis(5)),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
        }
    }
}

fn short(s: &str) -> String {
    let first = s.lines().next().unwrap_or(s);
    first.to_string()
}

fn start(exe: &Path, args: &[String]) -> std::io::Result<Proc> {
    let mut child = Command::new(exe)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()?;
    let (Some(mut stdin), Some(mut stdout), Some(mut stderr)) =
        (child.stdin.take(), child.stdout.take(), child.stderr.take())
    else {
        let _ = child.kill();
        let _ = child.wait();
        return Err(std::io::Error::other("no pipes to the program"));
    };
    let (to_child, requests) = mpsc::channel::<Vec<u8>>();
    std::thread::spawn(move || {
        for line in requests {
            if stdin.write_all(&line).and_then(|_| stdin.flush()).is_err() {
                break;
            }
        }
        // Dropping stdin here closes the program's input.
    });
    let (tx, from_child) = mpsc::channel::<Chunk>();
    std::thread::spawn(move || {
        let mut buf = vec![0u8; 64 * 1024];
        loop {
            match stdout.read(&mut buf) {
                Ok(0) => {
                    let _ = tx.send(Chunk::End(None));
                    break;
                }
                Ok(n) => {
                    if tx.send(Chunk::Data(buf[..n].to_vec())).is_err() {
                        break;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    let _ = tx.send(Chunk::End(Some(e)));
                    break;
                }
            }
        }
    });
    let kept = Arc::new(Mutex::new(Vec::new()));
    let sink = kept.clone();
    let (done_tx, stderr_done) = mpsc::channel::<()>();
    std::thread::spawn(move || {
        let mut buf = vec![0u8; 4096];
        loop {
            match stderr.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    let mut k = sink.lock().unwrap_or_else(|e| e.into_inner());
                    k.extend_from_slice(&buf[..n]);
                    if k.len() > STDERR_KEEP {
                        let cut = k.len() - STDERR_KEEP;
                        k.drain(..cut);
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(_) => break,
            }
        }
        let _ = done_tx.send(());
    });
    Ok(Proc {
        child,
        to_child: Some(to_child),
        from_child,
        pending: Vec::new(),
        stderr: kept,
        stderr_done,
        failed: None,
    })
}

/// Formats a detail as C's `%g` would for the values that occur (plain decimals, or an
/// exponent for huge ones such as RI_INFINITY), so any program's `atof`/`float()` reads it.
pub fn format_detail(d: f32) -> String {
    if !d.is_finite() || d >= 1e15 {
        "1e+38".into()
    } else if d == d.trunc() {
        format!("{}", d as i64)
    } else {
        format!("{d}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sh(script: &str) -> (std::path::PathBuf, Vec<String>) {
        ("/bin/sh".into(), vec!["-c".to_string(), script.to_string()])
    }

    #[test]
    fn a_looping_program_answers_each_request() {
        let (exe, args) =
            sh(r#"while read d rest; do echo "Sphere $d -1 1 360"; printf '\377'; done"#);
        let mut p = Programs::default();
        let t = Duration::from_secs(10);
        let a = p.request("k", &exe, &args, b"12 x\n", t).unwrap();
        assert_eq!(a, b"Sphere 12 -1 1 360\n");
        let b = p.request("k", &exe, &args, b"7 y\n", t).unwrap();
        assert_eq!(b, b"Sphere 7 -1 1 360\n");
        assert!(p.close_all().is_empty());
    }

    #[test]
    fn a_program_that_exits_early_is_an_error_and_is_not_rerun() {
        let (exe, args) = sh("read line; echo 'Sphere 1 -1 1 360'; echo oops >&2; exit 3");
        let mut p = Programs::default();
        let e = p
            .request("k", &exe, &args, b"1 x\n", Duration::from_secs(10))
            .unwrap_err();
        assert!(e.first);
        assert!(
            e.message.contains("before ending its reply"),
            "{}",
            e.message
        );
        assert!(e.message.contains("bytes of RIB dropped"), "{}", e.message);
        let again = p
            .request("k", &exe, &args, b"1 x\n", Duration::from_secs(10))
            .unwrap_err();
        assert!(!again.first);
        assert!(p.close_all().is_empty());
    }

    #[test]
    fn a_silent_program_times_out_and_is_killed() {
        let (exe, args) = sh("sleep 30");
        let mut p = Programs::default();
        let e = p
            .request("k", &exe, &args, b"1 x\n", Duration::from_millis(300))
            .unwrap_err();
        assert!(e.message.contains("killed"), "{}", e.message);
    }

    #[test]
    fn a_missing_program_cannot_start() {
        let mut p = Programs::default();
        let e = p
            .request(
                "k",
                Path::new("/nonexistent/arbor-no-such-program"),
                &[],
                b"1 x\n",
                Duration::from_secs(1),
            )
            .unwrap_err();
        assert!(e.message.contains("cannot start"), "{}", e.message);
    }

    #[test]
    fn details_print_like_percent_g() {
        assert_eq!(format_detail(1200.0), "1200");
        assert_eq!(format_detail(0.5), "0.5");
        assert_eq!(format_detail(f32::INFINITY), "1e+38");
    }
}
