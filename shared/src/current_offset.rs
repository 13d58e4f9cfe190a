//! Current-sensor offset calibration at start-up (filled by the firmware work).
