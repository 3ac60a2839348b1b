//! Data attachments.
