//! `camsim slurm` on a real one-node Slurm cluster (tests/slurm/cluster.sh:
//! munged + slurmctld + slurmd on this host, config in a temp dir): the
//! 12-variant sweep as a 4-task array with its merge job equals a
//! single-process `camsim run`; a task killed mid-run and resubmitted alone
//! completes the sweep with no lost or duplicated rows; the printed script
//! passes `sbatch --test-only`.
//!
//! Needs root and slurm-wlm + munge (.ci/run installs them). Without them the
//! cluster test prints a note and passes, unless the CI variable is set: then
//! it fails. The tests without a cluster run everywhere.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const GRID12: &str = "tests/experiments/grid12.kdl";

fn camsim(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_camsim"));
    c.args(args);
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn on_path(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| text(&o.stdout).trim() == "0")
}

/// Rows of a results.csv with the timing columns (render_s, total_s, the
/// last two: they differ between runs) split off. Every other field is
/// compared as text: values are written in shortest round-trip form, so equal
/// text is equal bits.
fn rows(p: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut r = csv::Reader::from_path(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let head: Vec<String> = r.headers().unwrap().iter().map(str::to_string).collect();
    assert_eq!(&head[head.len() - 2..], ["render_s", "total_s"]);
    let rows = r
        .records()
        .map(|x| {
            let mut v: Vec<String> = x.unwrap().iter().map(str::to_string).collect();
            for t in v.split_off(v.len() - 2) {
                let s: f64 = t.parse().unwrap_or_else(|_| panic!("timing '{t}'"));
                assert!(s >= 0.0 && s.is_finite(), "timing {s}");
            }
            v
        })
        .collect();
    (head, rows)
}

/// The single-process reference run of grid12.
fn single_run(dir: &Path) -> PathBuf {
    let out = dir.join("single");
    let o = camsim(
        &[
            "run",
            GRID12,
            "--threads",
            "2",
            "--out",
            out.to_str().unwrap(),
        ],
        &[],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    out.join("grid12/results.csv")
}

// ---------------------------------------------------------------- no cluster

#[test]
fn submit_without_slurm_is_a_clear_error_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // A PATH with no sbatch on it.
    let o = camsim(
        &["slurm", GRID12, "--out", out.to_str().unwrap(), "--submit"],
        &[("PATH", tmp.path().to_str().unwrap())],
    );
    assert_eq!(o.status.code(), Some(3), "{}", text(&o.stderr));
    let e = text(&o.stderr);
    assert!(e.contains("sbatch is not on PATH"), "{e}");
    assert!(e.contains("apt-get install slurm-wlm munge"), "{e}");
    assert!(!out.exists(), "nothing is written when it cannot submit");
}

#[test]
fn scripts_shard_the_sweep_and_merge_it() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = camsim(
        &[
            "slurm",
            GRID12,
            "--tasks",
            "4",
            "--cpus-per-task",
            "3",
            "--partition",
            "gpu",
            "--out",
            out.to_str().unwrap(),
        ],
        &[],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let dir = out.join("slurm/camsim-grid12");
    let array = std::fs::read_to_string(dir.join("array.sbatch")).unwrap();
    let merge = std::fs::read_to_string(dir.join("merge.sbatch")).unwrap();
    assert_eq!(text(&o.stdout), array, "stdout is the array script");
    for l in [
        "#SBATCH --array=1-4\n",
        "#SBATCH --cpus-per-task=3\n",
        "#SBATCH --partition=gpu\n",
        "--shard \"$((SLURM_ARRAY_TASK_ID))/4\"",
        "--threads \"${SLURM_CPUS_PER_TASK:-1}\"",
    ] {
        assert!(array.contains(l), "array script lacks {l:?}:\n{array}");
    }
    assert!(
        merge.contains("#SBATCH --kill-on-invalid-dep=yes\n"),
        "{merge}"
    );
    assert!(
        merge.contains(&format!(
            "merge {}/shard-{{1..4}}-of-4 --out {}",
            dir.display(),
            out.display()
        )),
        "{merge}"
    );
    // #SBATCH lines come before the first command, or sbatch ignores them.
    for s in [&array, &merge] {
        let lines: Vec<&str> = s.lines().collect();
        let first_cmd = lines.iter().position(|l| !l.starts_with('#')).unwrap();
        let last_directive = lines
            .iter()
            .rposition(|l| l.starts_with("#SBATCH"))
            .unwrap();
        assert!(last_directive < first_cmd, "{s}");
        let st = Command::new("bash").args(["-n", "-c", s]).status().unwrap();
        assert!(st.success(), "bash -n rejects:\n{s}");
    }
    let stderr = text(&o.stderr);
    assert!(stderr.contains("sbatch --dependency=afterok:"), "{stderr}");
}

#[test]
fn bad_sweeps_are_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o_s = out.to_str().unwrap();
    let o = camsim(&["slurm", GRID12, "--tasks", "13", "--out", o_s], &[]);
    assert_eq!(o.status.code(), Some(3));
    assert!(
        text(&o.stderr).contains("largest experiment has 12 variants"),
        "{}",
        text(&o.stderr)
    );
    let o = camsim(&["slurm", GRID12, "--tasks", "0", "--out", o_s], &[]);
    assert_eq!(o.status.code(), Some(2), "usage error");
    let bad = tmp.path().join("bad.kdl");
    std::fs::write(&bad, "experiment \"b\" {\n    render spp=-3\n}\n").unwrap();
    let o = camsim(&["slurm", bad.to_str().unwrap(), "--out", o_s], &[]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("bad.kdl:2:"),
        "{}",
        text(&o.stderr)
    );
    let o = camsim(&["slurm", GRID12, "--out", "with space"], &[]);
    assert_eq!(o.status.code(), Some(3));
    assert!(!out.exists());
    assert!(!Path::new("with space").exists());
}

// ---------------------------------------------------------------- the cluster

/// A running one-node cluster; stops its daemons (by pid) when dropped.
struct Cluster {
    dir: PathBuf,
    conf: String,
}

impl Cluster {
    fn start(dir: PathBuf) -> Self {
        std::fs::create_dir_all(&dir).unwrap();
        // Two free ports, so a Slurm already on this machine is not disturbed.
        let ports: Vec<u16> = (0..2)
            .map(|_| std::net::TcpListener::bind("127.0.0.1:0").unwrap())
            .collect::<Vec<_>>()
            .iter()
            .map(|l| l.local_addr().unwrap().port())
            .collect();
        let o = Command::new("bash")
            .arg("tests/slurm/cluster.sh")
            .arg("start")
            .arg(&dir)
            .arg(ports[0].to_string())
            .arg(ports[1].to_string())
            .output()
            .unwrap();
        let c = Cluster {
            conf: dir.join("slurm.conf").to_string_lossy().into_owned(),
            dir,
        };
        assert!(
            o.status.success(),
            "cluster.sh start: {}{}",
            text(&o.stdout),
            text(&o.stderr)
        );
        c
    }

    fn cmd(&self, tool: &str, args: &[&str]) -> Output {
        Command::new(tool)
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .output()
            .unwrap()
    }

    /// `JobState` of every record of a job (one per array task).
    fn states(&self, id: &str) -> Vec<(String, String)> {
        let o = self.cmd("scontrol", &["-o", "show", "job", id]);
        assert!(o.status.success(), "scontrol: {}", text(&o.stderr));
        text(&o.stdout)
            .lines()
            .map(|l| {
                let field = |k: &str| {
                    l.split_whitespace()
                        .find_map(|w| w.strip_prefix(k))
                        .unwrap_or("")
                        .to_string()
                };
                let task = field("ArrayTaskId=");
                (task, field("JobState="))
            })
            .collect()
    }

    /// Wait until every record of the job has ended; its final states.
    fn wait(&self, id: &str, logs: &Path) -> Vec<(String, String)> {
        let t0 = Instant::now();
        loop {
            let s = self.states(id);
            let ended = |st: &str| {
                !matches!(
                    st,
                    "PENDING"
                        | "RUNNING"
                        | "CONFIGURING"
                        | "COMPLETING"
                        | "SUSPENDED"
                        | "REQUEUED"
                        | "RESIZING"
                )
            };
            if !s.is_empty() && s.iter().all(|(_, st)| ended(st)) {
                return s;
            }
            if t0.elapsed() > Duration::from_secs(300) {
                panic!(
                    "job {id} still {s:?} after 300 s\n{}",
                    self.diagnostics(logs)
                );
            }
            std::thread::sleep(Duration::from_millis(250));
        }
    }

    fn diagnostics(&self, logs: &Path) -> String {
        let mut s = String::new();
        for p in [logs.to_path_buf(), self.dir.clone()] {
            if let Ok(rd) = std::fs::read_dir(&p) {
                for e in rd.flatten() {
                    let n = e.file_name().to_string_lossy().to_string();
                    if n.ends_with(".out") || n.ends_with(".log") {
                        let t = std::fs::read_to_string(e.path()).unwrap_or_default();
                        let tail: String = t
                            .chars()
                            .rev()
                            .take(3000)
                            .collect::<Vec<_>>()
                            .into_iter()
                            .rev()
                            .collect();
                        s.push_str(&format!("==> {} <==\n{tail}\n", e.path().display()));
                    }
                }
            }
        }
        s
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // Jobs first (a failed test may leave one hanging on the FIFO below):
        // their slurmstepd outlives slurmd. Only this cluster's jobs exist.
        let _ = self.cmd("scancel", &["--user=root"]);
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(15)
            && self
                .cmd("squeue", &["-h", "-t", "PD,R,CG"])
                .stdout
                .iter()
                .any(|b| !b.is_ascii_whitespace())
        {
            std::thread::sleep(Duration::from_millis(200));
        }
        let _ = Command::new("bash")
            .arg("tests/slurm/cluster.sh")
            .arg("stop")
            .arg(&self.dir)
            .status();
    }
}

fn job_ids(o: &Output) -> (String, String) {
    let s = text(&o.stdout);
    let get = |k: &str| {
        s.lines()
            .find_map(|l| l.strip_prefix(k))
            .unwrap_or_else(|| panic!("no {k} in stdout: {s}"))
            .to_string()
    };
    (get("array_job="), get("merge_job="))
}

#[test]
fn slurm_array_sweep_merges_to_the_single_process_results() {
    let tools = [
        "munged",
        "slurmctld",
        "slurmd",
        "sbatch",
        "scontrol",
        "scancel",
        "sinfo",
    ];
    let missing: Vec<&str> = tools.iter().copied().filter(|t| !on_path(t)).collect();
    if !missing.is_empty() || !is_root() {
        let why = format!(
            "needs root and slurm-wlm + munge (missing: {missing:?}, root: {})",
            is_root()
        );
        if std::env::var_os("CI").is_some() {
            panic!("CI is set but the Slurm cluster test cannot run: {why}");
        }
        eprintln!("note: skipping the Slurm cluster test: {why}; apt-get install slurm-wlm munge");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let reference = single_run(tmp.path());
    let (ref_head, ref_rows) = rows(&reference);
    assert_eq!(ref_rows.len(), 36, "12 variants × 3 figures");
    let cluster = Cluster::start(tmp.path().join("cluster"));
    let env = [("SLURM_CONF", cluster.conf.as_str())];

    // 1. The printed script is one that sbatch --test-only accepts; a wrong
    //    partition in it is refused (so the check can fail).
    for (partition, ok) in [(None, true), (Some("no-such-partition"), false)] {
        let out = tmp.path().join("test-only");
        let mut args = vec![
            "slurm",
            GRID12,
            "--tasks",
            "4",
            "--out",
            out.to_str().unwrap(),
        ];
        if let Some(p) = partition {
            args.extend(["--partition", p]);
        }
        let o = camsim(&args, &[]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        let mut sb = Command::new("sbatch")
            .arg("--test-only")
            .env("SLURM_CONF", &cluster.conf)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        use std::io::Write;
        sb.stdin.take().unwrap().write_all(&o.stdout).unwrap();
        let r = sb.wait_with_output().unwrap();
        assert_eq!(
            r.status.success(),
            ok,
            "sbatch --test-only: {}",
            text(&r.stderr)
        );
    }

    // sbatch refusing a job is an error (exit 3) with its reason.
    let out = tmp.path().join("refused");
    let o = camsim(
        &[
            "slurm",
            GRID12,
            "--partition",
            "no-such-partition",
            "--out",
            out.to_str().unwrap(),
            "--submit",
        ],
        &env,
    );
    assert_eq!(o.status.code(), Some(3));
    assert!(
        text(&o.stderr).contains("invalid partition"),
        "{}",
        text(&o.stderr)
    );
    assert!(o.stdout.is_empty(), "no job id is printed");

    // 2. The whole sweep: 4 array tasks, then the merge job.
    let out = tmp.path().join("sweep");
    let logs = out.join("slurm/camsim-grid12/logs");
    let o = camsim(
        &[
            "slurm",
            GRID12,
            "--tasks",
            "4",
            "--out",
            out.to_str().unwrap(),
            "--submit",
        ],
        &env,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let (array, merge) = job_ids(&o);
    let merged = cluster.wait(&merge, &logs);
    let tasks = cluster.wait(&array, &logs);
    assert_eq!(
        merged,
        [(String::new(), "COMPLETED".to_string())],
        "{}",
        cluster.diagnostics(&logs)
    );
    assert_eq!(tasks.len(), 4);
    assert!(tasks.iter().all(|(_, s)| s == "COMPLETED"), "{tasks:?}");
    let (head, got) = rows(&out.join("grid12/results.csv"));
    assert_eq!(head, ref_head);
    assert_eq!(got, ref_rows, "Slurm sweep ≠ single-process run");
    assert!(out.join("grid12/report.html").is_file() && out.join("index.html").is_file());

    // 3. Kill one task mid-run, resubmit only its index. Task 2 runs plan
    //    indices 1, 5, 9; a FIFO where variant 5's results would be makes the
    //    task hang after variant 1 is written (as on a stuck file system),
    //    and it is cancelled there.
    let out = tmp.path().join("killed");
    let logs = out.join("slurm/camsim-grid12/logs");
    let plan = camsim(&["plan", "--json", GRID12], &[]);
    let plan: serde_json::Value = serde_json::from_slice(&plan.stdout).unwrap();
    let short = |k: usize| plan["variants"][k]["hash"].as_str().unwrap()[..16].to_string();
    let variants = out.join("slurm/camsim-grid12/shard-2-of-4/grid12/variants");
    std::fs::create_dir_all(&variants).unwrap();
    let fifo = variants.join(format!("{}.csv", short(5)));
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let o = camsim(
        &[
            "slurm",
            GRID12,
            "--tasks",
            "4",
            "--out",
            out.to_str().unwrap(),
            "--submit",
        ],
        &env,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let (array, merge) = job_ids(&o);
    let first = variants.join(format!("{}.csv", short(1)));
    let t0 = Instant::now();
    while !(first.exists()
        && cluster
            .states(&array)
            .iter()
            .any(|(t, s)| t == "2" && s == "RUNNING"))
    {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "task 2 never got to its second variant\n{}",
            cluster.diagnostics(&logs)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let c = cluster.cmd("scancel", &[&format!("{array}_2")]);
    assert!(c.status.success(), "scancel: {}", text(&c.stderr));
    let tasks = cluster.wait(&array, &logs);
    let by_task = |t: &str| tasks.iter().find(|(x, _)| x == t).unwrap().1.clone();
    assert_eq!(by_task("2"), "CANCELLED", "{tasks:?}");
    for t in ["1", "3", "4"] {
        assert_eq!(by_task(t), "COMPLETED", "{tasks:?}");
    }
    // The merge job's afterok can no longer be met: it is cancelled, not run.
    assert_eq!(cluster.wait(&merge, &logs)[0].1, "CANCELLED");
    assert!(!out.join("grid12/results.csv").exists());
    std::fs::remove_file(&fifo).unwrap();

    // Resubmit task 2 alone, with the command the array script gives for it.
    let script = std::fs::read_to_string(out.join("slurm/camsim-grid12/array.sbatch")).unwrap();
    let rerun = script
        .lines()
        .find_map(|l| l.strip_prefix("#   ").filter(|c| c.contains("--array=2 ")))
        .unwrap_or_else(|| panic!("no re-run line for task 2 in:\n{script}"));
    let r = Command::new("bash")
        .args(["-c", &format!("set -e; {rerun}; echo \"array=$jid\"")])
        .env("SLURM_CONF", &cluster.conf)
        .output()
        .unwrap();
    assert!(r.status.success(), "{rerun}: {}", text(&r.stderr));
    let r = text(&r.stdout);
    let merge = r
        .lines()
        .find_map(|l| l.strip_prefix("Submitted batch job "))
        .unwrap_or_else(|| panic!("{r}"))
        .to_string();
    let array = r.lines().find_map(|l| l.strip_prefix("array=")).unwrap();
    let tasks = cluster.wait(array, &logs);
    assert_eq!(tasks, [("2".to_string(), "COMPLETED".to_string())]);
    assert_eq!(cluster.wait(&merge, &logs)[0].1, "COMPLETED");
    // Task 2's rerun skipped the variant it had finished before the kill.
    let m: serde_json::Value = serde_json::from_slice(
        &std::fs::read(
            out.join("slurm/camsim-grid12/shard-2-of-4/grid12/manifest.shard-2-of-4.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let status = |k: usize| m["variants"][k]["status"].as_str().unwrap().to_string();
    assert_eq!(
        [status(1), status(5), status(9)],
        ["cached", "done", "done"]
    );
    // No lost and no duplicated rows: equal to the single-process run.
    let (head, got) = rows(&out.join("grid12/results.csv"));
    assert_eq!(head, ref_head);
    assert_eq!(got, ref_rows, "resubmitted sweep ≠ single-process run");
}
