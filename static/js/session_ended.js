// A request refused because the session ended fails with an Error with `sessionEnded`, and
// request.js shows the "log in again" banner for it: pages add no error text of their own.

export const sessionEnded = (err) => err?.sessionEnded === true;

// An error handler that says `err.message` through `say(text, "error")`, unless the session ended.
export const sayFailure = (say) => (err) => {
  if (!sessionEnded(err)) say(err.message, "error");
};
