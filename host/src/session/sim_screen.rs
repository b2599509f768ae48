//! The session's prompts shown to the simulated person ([`imucal_hil_sim::board::Screen`]), as
//! a person holding a real board reads them off the terminal: the corner named, the turning
//! for the magnetometer, the rest at the end. Without it the simulated person guesses what the
//! host wants from the firmware's traffic alone.

use imucal_hil_sim::board::Screen;
use imucal_hil_sim::serve::SimHandle;

use super::events::SessionEvent;

/// What the screen asks of the person after `event`, when the event changes it.
pub fn screen_of(event: &SessionEvent<'_>) -> Option<Screen> {
    match event {
        SessionEvent::Prompt { target, .. } => Some(Screen::Pose {
            up: [target.up.x, target.up.y, target.up.z],
        }),
        SessionEvent::MagPrompt => Some(Screen::Turn),
        SessionEvent::RestPrompt => Some(Screen::Rest),
        _ => None,
    }
}

/// A tap ([`super::events::Tapped`]) that shows the session's prompts to the person holding
/// the simulated board behind `handle`.
pub fn shown_on(handle: &SimHandle) -> impl FnMut(&SessionEvent<'_>) + '_ {
    |event| {
        if let Some(screen) = screen_of(event) {
            handle.show(screen);
        }
    }
}
