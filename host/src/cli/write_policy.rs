//! Whether a fitted set may be written to a board: a poor verdict is never written unless the
//! user says so (`--accept-poor`, or an explicit "y" at the prompt, whose default is "no").
//! Whether a command may write its output files is [`outputs`].

use std::io::{BufRead, IsTerminal, Write};

use imucal::session::VerdictLevel;

mod outputs;

pub(super) use outputs::{check_outputs, Output};

/// The user's standing answers for writing a set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct WritePolicy {
    /// `--yes`: write a usable (good or marginal) set without asking.
    pub yes: bool,
    /// `--accept-poor`: write a set whose verdict is poor.
    pub accept_poor: bool,
}

/// What became of a set offered for writing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum WriteDecision {
    /// Write it.
    Write,
    /// The user answered no.
    Declined,
    /// Not written because its verdict is poor (and neither `--accept-poor` nor "y" said so).
    RefusedPoor,
    /// Not written: nobody to ask (standard input is not a terminal) and no `--yes`.
    NoOneToAsk,
}

impl WritePolicy {
    /// Decides without asking when the flags or a non-interactive input settle it; otherwise
    /// asks on the terminal with `question` (a poor verdict defaults to "no").
    pub(super) fn decide(&self, level: VerdictLevel, question: &str) -> WriteDecision {
        if let Some(settled) = self.settled(level, std::io::stdin().is_terminal()) {
            return settled;
        }
        let poor = level == VerdictLevel::Poor;
        let (suffix, choices) = if poor {
            (" (the verdict is poor)", "[y/N]")
        } else {
            ("", "[Y/n]")
        };
        let Some(answer) = ask(&format!("{question}{suffix}? {choices} ")) else {
            return WriteDecision::Declined;
        };
        match (answer.as_str(), poor) {
            ("y" | "yes", _) => WriteDecision::Write,
            ("", false) => WriteDecision::Write,
            ("", true) => WriteDecision::RefusedPoor,
            _ => WriteDecision::Declined,
        }
    }
}

impl WritePolicy {
    /// The decision when no question is needed: `--accept-poor` for a poor set, `--yes` for
    /// the rest; without `--yes` and without a terminal to ask, nothing is written (a board is
    /// changed only when someone said so); `None` means ask.
    fn settled(&self, level: VerdictLevel, interactive: bool) -> Option<WriteDecision> {
        let poor = level == VerdictLevel::Poor;
        if poor && self.accept_poor {
            Some(WriteDecision::Write)
        } else if poor && (self.yes || !interactive) {
            Some(WriteDecision::RefusedPoor)
        } else if self.yes {
            Some(WriteDecision::Write)
        } else if !interactive {
            Some(WriteDecision::NoOneToAsk)
        } else {
            None
        }
    }
}

/// Asks `prompt` on the terminal; the answer trimmed and in lower case, `None` when standard
/// input cannot be read.
fn ask(prompt: &str) -> Option<String> {
    say_part!("{prompt}");
    let _ = std::io::stderr().flush();
    let mut answer = String::new();
    std::io::stdin().lock().read_line(&mut answer).ok()?;
    Some(answer.trim().to_lowercase())
}

/// Consent to a destructive step: `--yes`, or a "y" typed at the terminal (default "no").
pub(super) struct Confirmation {
    yes: bool,
}

impl Confirmation {
    /// Refused at once, before anything is done, when there is neither `--yes` nor a terminal
    /// to ask; `refusal` names the flag that confirms.
    pub(super) fn possible(yes: bool, refusal: &str) -> anyhow::Result<Self> {
        anyhow::ensure!(yes || std::io::stdin().is_terminal(), "{refusal}");
        Ok(Self { yes })
    }

    /// Asks `question` unless `--yes` answered it; an answer other than "y" is an error.
    pub(super) fn ask(&self, question: &str) -> anyhow::Result<()> {
        if self.yes {
            return Ok(());
        }
        match ask(&format!("{question}? [y/N] ")).as_deref() {
            Some("y" | "yes") => Ok(()),
            _ => anyhow::bail!("not confirmed; nothing was changed"),
        }
    }
}

/// The error ending a command that wrote nothing because there was nobody to ask; `later` says
/// how to write the saved set afterwards.
pub(super) fn not_asked(what: &str, later: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{what} was saved but not written to the board: standard input is not a terminal, so \
         there was nobody to ask, and --yes was not given; run with --yes to write without \
         asking, or {later}"
    )
}

/// The error ending a command that wrote nothing because the verdict was poor.
pub(super) fn refused_poor(what: &str, params: &std::path::Path) -> anyhow::Error {
    anyhow::anyhow!(
        "{what} was not written to the board because its verdict is poor (see the reasons \
         above); redo the positions the reasons name, or, to use it anyway, run again with \
         --accept-poor or write the saved file with `imucal flash {}`",
        params.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const YES: WritePolicy = WritePolicy {
        yes: true,
        accept_poor: false,
    };

    #[test]
    fn yes_writes_a_usable_set_but_not_a_poor_one() {
        assert_eq!(
            YES.settled(VerdictLevel::Good, true),
            Some(WriteDecision::Write)
        );
        assert_eq!(
            YES.settled(VerdictLevel::Marginal, true),
            Some(WriteDecision::Write)
        );
        assert_eq!(
            YES.settled(VerdictLevel::Poor, true),
            Some(WriteDecision::RefusedPoor)
        );
    }

    #[test]
    fn accept_poor_writes_a_poor_set_with_or_without_a_terminal() {
        let accept = WritePolicy {
            yes: false,
            accept_poor: true,
        };
        assert_eq!(
            accept.settled(VerdictLevel::Poor, true),
            Some(WriteDecision::Write)
        );
        assert_eq!(
            accept.settled(VerdictLevel::Poor, false),
            Some(WriteDecision::Write)
        );
    }

    #[test]
    fn without_a_terminal_a_poor_set_is_refused_and_with_one_the_user_is_asked() {
        let plain = WritePolicy {
            yes: false,
            accept_poor: false,
        };
        assert_eq!(
            plain.settled(VerdictLevel::Poor, false),
            Some(WriteDecision::RefusedPoor)
        );
        assert_eq!(plain.settled(VerdictLevel::Poor, true), None);
        assert_eq!(plain.settled(VerdictLevel::Good, true), None);
    }

    #[test]
    fn without_yes_and_without_a_terminal_a_good_set_is_not_written() {
        let plain = WritePolicy {
            yes: false,
            accept_poor: false,
        };
        for level in [VerdictLevel::Good, VerdictLevel::Marginal] {
            assert_eq!(
                plain.settled(level, false),
                Some(WriteDecision::NoOneToAsk),
                "{level:?}"
            );
        }
    }
}
