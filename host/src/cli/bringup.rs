//! `rig bringup`: the guided first power-up ([`crate::bringup`]) on a board or a virtual
//! rig: each step with pass/fail and what to check; `--json`; exit 1 when a step fails.
//! On a real rig (or with `--operator`) the person is prompted on stderr; on a virtual rig
//! its plant is the person's hands, and `--inject` builds a fault into it to rehearse a
//! failed step.

use std::io::Write;
use std::process::ExitCode;

use clap::Args;

use super::connect::{DeviceOpts, interrupt_flag};
use crate::RigError;
use crate::bringup::{self, Hands, Injection, OperatorHands, Status, VirtualHands};
use crate::experiment::bench::Operator;

/// Arguments of `rig bringup`.
#[derive(Debug, Args)]
pub struct BringupArgs {
    /// Print one JSON object (`passed`, `steps`: name, status, detail, check).
    #[arg(long)]
    pub json: bool,
    /// Prompt the operator for each set-up even on a virtual rig (to rehearse).
    #[arg(long)]
    pub operator: bool,
    /// With --sim: build this fault into the virtual rig first, to see the step it fails.
    #[arg(long, value_enum, value_name = "FAULT")]
    pub inject: Option<Injection>,
}

/// Runs `rig bringup`.
pub fn run(a: BringupArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    if a.inject.is_some() && !dev.sim {
        return Err(RigError::BadValue {
            what: "--inject".into(),
            why:
                "builds a fault into the virtual rig: add --sim (a real board's faults are its own)"
                    .into(),
        });
    }
    let stop = interrupt_flag();
    let mut session = dev.connect()?;
    let device = session.device.take();
    if let (Some(fault), Some(d)) = (a.inject, device.as_ref()) {
        fault.apply(d);
    }
    let quiet = a.json;
    let report = {
        let mut virtual_hands;
        let mut operator_hands;
        let hands: &mut dyn Hands = match device.as_ref() {
            Some(d) if !a.operator => {
                virtual_hands = VirtualHands(d);
                &mut virtual_hands
            }
            d => {
                operator_hands = OperatorHands {
                    operator: Operator::stdin(true, stop),
                    device: d,
                };
                &mut operator_hands
            }
        };
        bringup::run(&mut session, hands, &mut |s| {
            if !quiet {
                let word = match s.status {
                    Status::Pass => "pass",
                    Status::Fail => "FAIL",
                    Status::Skip => "skip",
                    Status::NotRun => "not run",
                };
                println!("{word:>7}  {:<17} {}", s.name, s.detail);
                if !s.check.is_empty() {
                    println!("         check: {}", s.check);
                }
            }
        })
    };
    // The client goes before the virtual device it talks to.
    drop(session);
    drop(device);
    let report = report?;
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &report)?;
    } else {
        for s in report.steps.iter().filter(|s| s.status == Status::NotRun) {
            writeln!(out, "not run  {:<17} {}", s.name, s.detail)?;
        }
        writeln!(
            out,
            "{}",
            if report.passed {
                "bring-up passed: the board is ready for `rig calibrate` (docs/bench.md: what only hardware can confirm)"
            } else {
                "bring-up FAILED: fix the step above (its `check` line), then run `rig bringup` again"
            }
        )?;
    }
    Ok(if report.passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
