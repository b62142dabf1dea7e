//! `camsim slurm EXPERIMENT…`: a sweep as a Slurm job array plus a merge job.
//!
//! Writes two batch scripts into `<out>/slurm/<job name>/`:
//!
//! - `array.sbatch`: one array task per shard (`--array=1-N`); task `i` runs
//!   `camsim run EXPERIMENT… --shard $((SLURM_ARRAY_TASK_ID))/N` with
//!   `--threads ${SLURM_CPUS_PER_TASK}` into its own `shard-<i>-of-<N>/`.
//! - `merge.sbatch`: `camsim merge` of the N shard directories into `<out>`
//!   and `camsim report <out>` (the same files as `camsim run --out <out>`);
//!   submitted with
//!   `--dependency=afterok:<array job id>`, and `--kill-on-invalid-dep=yes`
//!   so that it is cancelled, not left pending, when a task fails.
//!
//! Without `--submit` the array script is printed on stdout (so
//! `camsim slurm … | sbatch --test-only` checks it) and the submit commands
//! on stderr. With `--submit` both jobs are submitted through `sbatch` and
//! stdout gets `array_job=<id>` and `merge_job=<id>` (shell assignments).
//!
//! The scripts run the camsim binary that wrote them (its absolute path: the
//! plan hashes include the camsim version) in the directory it was called
//! from (`#SBATCH --chdir`), so relative experiment and output paths mean
//! what they meant here. A failed or cancelled task is re-run alone with
//! `sbatch --array=<i> array.sbatch`; its finished variants are skipped.
//!
//! Exit codes: 0 written (and submitted); 1 an invalid experiment (nothing
//! written); 2 usage; 3 I/O, no `sbatch` on this machine, or `sbatch` failed.

use camsim::experiment::{self, DocKind, Loader};
use camsim::{Error, Result};
use clap::Args;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Slurm's default MaxArraySize is 1001 (indices 0–1000).
const DEFAULT_MAX_TASKS: usize = 1000;

#[derive(Args)]
pub struct SlurmArgs {
    /// Experiment files (or directories of *.kdl files) swept together.
    #[arg(required = true, value_name = "EXPERIMENT")]
    pub paths: Vec<PathBuf>,
    /// Array tasks, one shard each [default: the largest experiment's
    /// variant count, at most 1000].
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub tasks: Option<u64>,
    /// CPUs of each array task (its render threads).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub cpus_per_task: u64,
    /// Slurm partition of both jobs [default: the cluster's default partition].
    #[arg(long)]
    pub partition: Option<String>,
    /// Results root: the merged results go to <out>/<experiment>/, the
    /// scripts, logs and shard directories to <out>/slurm/<job name>/.
    #[arg(long, default_value = "results")]
    pub out: PathBuf,
    /// Submit both jobs with sbatch and print their ids.
    #[arg(long)]
    pub submit: bool,
}

/// One experiment of the sweep.
struct Swept {
    file: PathBuf,
    name: String,
    variants: usize,
}

/// Everything the two scripts are made of.
pub struct Sweep {
    /// Experiment files, as given (relative to `chdir`).
    pub files: Vec<PathBuf>,
    /// `camsim-<experiment names>`: job name and sweep directory name.
    pub job_name: String,
    pub tasks: usize,
    pub cpus_per_task: u64,
    pub partition: Option<String>,
    pub out: PathBuf,
    /// Working directory of the jobs (absolute).
    pub chdir: PathBuf,
    /// The camsim binary the jobs run (absolute).
    pub camsim: PathBuf,
}

impl Sweep {
    /// `<out>/slurm/<job name>`, relative to `chdir` when `out` is.
    pub fn dir(&self) -> PathBuf {
        self.out.join("slurm").join(&self.job_name)
    }
    pub fn array_script(&self) -> PathBuf {
        self.dir().join("array.sbatch")
    }
    pub fn merge_script(&self) -> PathBuf {
        self.dir().join("merge.sbatch")
    }

    /// The commands that submit both jobs, and that re-run chosen tasks.
    fn submit_lines(&self, indices: &str) -> String {
        let array = sh(&self.chdir.join(self.array_script()));
        let merge = sh(&self.chdir.join(self.merge_script()));
        let only = if indices.is_empty() {
            String::new()
        } else {
            format!(" --array={indices}")
        };
        format!(
            "jid=$(sbatch --parsable{only} {array}) && sbatch --dependency=afterok:${{jid%;*}} {merge}"
        )
    }

    fn directives(&self, s: &mut String, name: &str, log: &str) {
        let _ = writeln!(s, "#SBATCH --job-name={name}");
        let _ = writeln!(s, "#SBATCH --cpus-per-task={}", self.cpus_per_task);
        if let Some(p) = &self.partition {
            let _ = writeln!(s, "#SBATCH --partition={p}");
        }
        let _ = writeln!(s, "#SBATCH --chdir={}", self.chdir.display());
        let _ = writeln!(
            s,
            "#SBATCH --output={}",
            self.dir().join("logs").join(log).display()
        );
    }

    /// The array script: task i runs shard i of N into its own directory.
    pub fn array(&self, names: &[(String, usize)]) -> String {
        let n = self.tasks;
        let i = n.min(2);
        let mut s = String::from("#!/bin/bash\n");
        let _ = writeln!(
            s,
            "# camsim {} sweep as a Slurm job array, written by `camsim slurm`.",
            env!("CARGO_PKG_VERSION")
        );
        for (name, v) in names {
            let _ = writeln!(s, "#   experiment '{name}': {v} variants over {n} shards");
        }
        let _ = writeln!(
            s,
            "# Submit with its merge job:\n#   {}",
            self.submit_lines("")
        );
        let _ = writeln!(
            s,
            "# Re-run failed or cancelled tasks only, e.g. task {i} (its finished variants are skipped):\n#   {}",
            self.submit_lines(&i.to_string())
        );
        s.push_str("#SBATCH --array=1-");
        let _ = writeln!(s, "{n}");
        self.directives(&mut s, &self.job_name, "shard-%a.%A.out");
        s.push_str("set -euo pipefail\n");
        let _ = write!(s, "exec {} run", sh(&self.camsim));
        for f in &self.files {
            let _ = write!(s, " {}", sh(f));
        }
        let _ = writeln!(
            s,
            " \\\n    --shard \"$((SLURM_ARRAY_TASK_ID))/{n}\" \\\n    --threads \"${{SLURM_CPUS_PER_TASK:-1}}\" \\\n    --out {}\"/shard-$((SLURM_ARRAY_TASK_ID))-of-{n}\"",
            sh(&self.dir())
        );
        s
    }

    /// The merge script: all N shard directories into `out`.
    pub fn merge(&self) -> String {
        let n = self.tasks;
        let mut s = String::from("#!/bin/bash\n");
        let _ = writeln!(
            s,
            "# Merges the shards of {} into {} (submit after the array job:\n#   sbatch --dependency=afterok:<array job id> {}).",
            sh(&self.array_script()),
            sh(&self.out),
            sh(&self.merge_script())
        );
        self.directives(&mut s, &format!("{}-merge", self.job_name), "merge.%j.out");
        s.push_str("#SBATCH --kill-on-invalid-dep=yes\n");
        s.push_str("set -euo pipefail\n");
        let _ = writeln!(
            s,
            "{} merge {}/shard-{{1..{n}}}-of-{n} --out {}",
            sh(&self.camsim),
            sh(&self.dir()),
            sh(&self.out)
        );
        s.push_str("# The HTML reports and index, as `camsim run` writes them.\n");
        let _ = writeln!(s, "exec {} report {}", sh(&self.camsim), sh(&self.out));
        s
    }
}

/// Quote a path for bash (single quotes unless it is plainly safe).
fn sh(p: &Path) -> String {
    let s = p.to_string_lossy();
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-+=:,@".contains(c))
    {
        s.into_owned()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// `#SBATCH` lines are not shell: a path there must be one plain word, and
/// `%` is a filename pattern in `--output`.
fn check_directive_path(what: &str, p: &Path) -> Result<()> {
    let s = p.to_string_lossy();
    if let Some(c) = s
        .chars()
        .find(|c| c.is_whitespace() || c.is_control() || "\"'\\%#".contains(*c))
    {
        return Err(Error::invalid(format!(
            "{what} '{s}' contains {c:?}, which an #SBATCH line cannot carry; use a path without it"
        )));
    }
    Ok(())
}

/// Job name from the experiment names: `camsim-a+b`, restricted to
/// `[A-Za-z0-9._+-]` and 64 characters.
fn job_name(names: &[&str]) -> String {
    let joined: String = names
        .join("+")
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._+-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .take(57)
        .collect();
    format!("camsim-{joined}")
}

/// Run `sbatch --parsable ARGS…` and return the job id it printed.
fn sbatch(args: &[String]) -> Result<String> {
    let out = Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .output()
        .map_err(|e| Error::invalid(format!("cannot run sbatch: {e}")))?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        return Err(Error::invalid(format!(
            "sbatch {} failed ({}): {}",
            args.join(" "),
            out.status,
            stderr.trim()
        )));
    }
    eprint!("{stderr}");
    // --parsable prints "<id>" or "<id>;<cluster>".
    let text = String::from_utf8_lossy(&out.stdout);
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(Error::invalid(format!(
            "sbatch {} printed no job id (stdout: '{}')",
            args.join(" "),
            text.trim()
        )));
    }
    Ok(id)
}

fn on_path(tool: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|paths| {
        std::env::split_paths(&paths).any(|d| {
            let p = d.join(tool);
            p.is_file()
                && std::fs::metadata(&p).is_ok_and(|m| {
                    use std::os::unix::fs::PermissionsExt;
                    m.permissions().mode() & 0o111 != 0
                })
        })
    })
}

pub fn slurm(a: SlurmArgs) -> Result<i32> {
    if a.submit && !on_path("sbatch") {
        return Err(Error::invalid(
            "--submit: sbatch is not on PATH, so Slurm is not installed on this machine. \
             Run `camsim slurm` on the cluster's login node, or copy the scripts written without \
             --submit there; to try Slurm on one machine as root: \
             `apt-get install slurm-wlm munge` and `tests/slurm/cluster.sh start DIR` \
             (see README, \"Scale-out: shards\")",
        ));
    }
    if let Some(p) = &a.partition
        && (p.is_empty() || !p.chars().all(|c| c.is_ascii_graphic() && c != '#'))
    {
        return Err(Error::invalid(format!(
            "--partition '{p}': expected a Slurm partition name"
        )));
    }
    // Validate and plan every experiment first: nothing is written for an invalid sweep.
    let mut swept: Vec<Swept> = Vec::new();
    let mut bad = false;
    for f in super::experiment::collect(&a.paths)? {
        match experiment::parse_file(&f, Loader::Disk) {
            Ok(p) if p.kind == DocKind::Setup => {}
            Ok(p) => match experiment::plan(&p, None) {
                Ok(pl) => {
                    if let Some(prev) = swept.iter().find(|s| s.name == pl.experiment) {
                        eprintln!(
                            "{}: experiment '{}' is also defined in {}; both would write {}",
                            f.display(),
                            pl.experiment,
                            prev.file.display(),
                            a.out.join(&pl.experiment).display()
                        );
                        bad = true;
                    }
                    swept.push(Swept {
                        file: f,
                        name: pl.experiment.clone(),
                        variants: pl.variants.len(),
                    });
                }
                Err(e) => {
                    eprint!("{e}");
                    bad = true;
                }
            },
            Err(e) => {
                eprint!("{e}");
                bad = true;
            }
        }
    }
    if bad {
        return Ok(1);
    }
    let Some(largest) = swept.iter().map(|s| s.variants).max() else {
        eprintln!("no experiments to sweep (only setups given)");
        return Ok(1);
    };
    let tasks = match a.tasks {
        Some(t) => usize::try_from(t).map_err(|_| Error::invalid("--tasks is too large"))?,
        None => largest.clamp(1, DEFAULT_MAX_TASKS),
    };
    if tasks > largest {
        return Err(Error::invalid(format!(
            "--tasks {tasks}: the largest experiment has {largest} variants, so {} tasks would have nothing to run",
            tasks - largest
        )));
    }
    let chdir =
        std::env::current_dir().map_err(|e| Error::invalid(format!("current directory: {e}")))?;
    let camsim = std::env::current_exe()
        .map_err(|e| Error::invalid(format!("path of the camsim binary: {e}")))?;
    check_directive_path("the current directory", &chdir)?;
    check_directive_path("--out", &a.out)?;
    let names: Vec<&str> = swept.iter().map(|s| s.name.as_str()).collect();
    let sweep = Sweep {
        files: swept.iter().map(|s| s.file.clone()).collect(),
        job_name: job_name(&names),
        tasks,
        cpus_per_task: a.cpus_per_task,
        partition: a.partition.clone(),
        out: a.out.clone(),
        chdir,
        camsim,
    };
    let counts: Vec<(String, usize)> = swept.iter().map(|s| (s.name.clone(), s.variants)).collect();
    let array = sweep.array(&counts);
    let merge = sweep.merge();
    let dir = sweep.dir();
    std::fs::create_dir_all(dir.join("logs")).map_err(|e| Error::io(&dir.join("logs"), e))?;
    camsim::diag::write_atomic(&sweep.array_script(), array.as_bytes())?;
    camsim::diag::write_atomic(&sweep.merge_script(), merge.as_bytes())?;
    if !a.submit {
        print!("{array}");
        eprintln!(
            "wrote {} ({tasks} tasks) and {}\nsubmit both with:\n  {}",
            sweep.array_script().display(),
            sweep.merge_script().display(),
            sweep.submit_lines("")
        );
        return Ok(0);
    }
    let array_id = sbatch(&[sweep.array_script().to_string_lossy().into_owned()])?;
    let merge_id = sbatch(&[
        format!("--dependency=afterok:{array_id}"),
        sweep.merge_script().to_string_lossy().into_owned(),
    ])
    .map_err(|e| {
        Error::invalid(format!(
            "array job {array_id} was submitted, but its merge job was not: {e}\n\
             submit it yourself: sbatch --dependency=afterok:{array_id} {}",
            sh(&sweep.merge_script())
        ))
    })?;
    println!("array_job={array_id}\nmerge_job={merge_id}");
    eprintln!(
        "array job {array_id} ({tasks} tasks, logs in {}), merge job {merge_id} → {}\n\
         watch: squeue -j {array_id},{merge_id}\n\
         re-run failed or cancelled tasks only, e.g. task {}:\n  {}",
        dir.join("logs").display(),
        sweep.out.display(),
        tasks.min(2),
        sweep.submit_lines(&tasks.min(2).to_string())
    );
    Ok(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// bash reads back exactly the path `sh` quoted.
    #[test]
    fn quoted_paths_survive_bash() {
        for p in ["plain/path.kdl", "it's here", "a b/$HOME/`x`", "-x", ""] {
            let o = Command::new("bash")
                .args(["-c", &format!("printf %s {}", sh(Path::new(p)))])
                .output()
                .unwrap();
            assert_eq!(String::from_utf8_lossy(&o.stdout), p);
        }
    }

    #[test]
    fn job_names_are_plain_words() {
        assert_eq!(job_name(&["grid12"]), "camsim-grid12");
        assert_eq!(job_name(&["a b", "c/d"]), "camsim-a_b+c_d");
        assert_eq!(job_name(&[&"x".repeat(100)]).len(), 64);
    }
}
