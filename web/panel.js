// The page's panel (issue 37): the room picker (#room, filled from /api/rooms), the detail
// checkbox (#detail), the publish token (#token), and loading the room's model description
// (/api/rooms/{id}: control points, bounds, capture, skinning) into state.room.
//
// The publish token: from the page's fragment (`#token=T`, which browsers never send to a
// server), else the page's query (`?token=T`: kept for old links, taken out of the address bar
// at once), else what this tab was given before (sessionStorage). It travels in the
// WebSocket's subprotocols (wire.js socketProtocols), never in a URL.

/**
 * Wires the panel's controls (`state.params`: the page's query), `onToken()` runs
 * when the token changes (the connection reconnects: the token is read at connection).
 * Returns {token(): the publish token, loadRoom()}.
 */
export function createPanel(state, { elements, onToken }) {
  const params = state.params;
  const { token: tokenInput, detail, room: roomSelect } = elements;
  const key = `crease-token-${state.roomId}`;

  const hashParams = new URLSearchParams(location.hash.slice(1));
  const urlToken = hashParams.get("token") || params.get("token");
  if (params.has("token") || hashParams.has("token")) {
    if (params.has("token")) console.warn("crease: a token in the page's query string reaches the server's logs; use #token= instead");
    params.delete("token");
    hashParams.delete("token");
    const hash = hashParams.toString();
    history.replaceState(null, "", `${location.pathname}?${params}${hash ? `#${hash}` : ""}`);
  }
  if (urlToken) sessionStorage.setItem(key, urlToken);
  tokenInput.value = urlToken || sessionStorage.getItem(key) || "";
  tokenInput.addEventListener("change", () => {
    sessionStorage.setItem(key, tokenInput.value);
    onToken();
  });
  detail.checked = state.level === "detail";
  detail.addEventListener("change", () => {
    params.set("level", detail.checked ? "detail" : "base");
    location.search = params.toString();
  });
  roomSelect.addEventListener("change", () => {
    params.set("room", roomSelect.value);
    location.search = params.toString();
  });

  /** Fills the room picker and loads state.room; throws naming the room when it cannot. */
  async function loadRoom() {
    const roomId = state.roomId;
    const list = await fetch("/api/rooms").then((r) => (r.ok ? r.json() : { rooms: [] }));
    // In a cluster (crease-server --nats) the list has every room of the cluster and its owner.
    const owners = new Map((list.cluster ?? []).map((r) => [r.room, r.owner]));
    const label = (id) => (owners.has(id) ? `${id} (on ${owners.get(id)})` : id);
    roomSelect.replaceChildren(
      ...[...new Set([roomId, ...list.rooms])].map((id) => new Option(label(id), id, false, id === roomId)),
    );
    const r = await fetch(`/api/rooms/${encodeURIComponent(roomId)}`);
    if (!r.ok) throw new Error(`room ${roomId}: ${(await r.text()).trim()}`);
    state.room = await r.json();
    // A room that skins with dual quaternions refuses palette streams (palette.js skins linearly).
    if (state.room.skinning === "dqs" && state.crease.encoding === "palette") {
      state.crease.encoding = "vertices";
      state.crease.paletteReason = "the room skins with dual quaternions";
    }
  }

  return { token: () => tokenInput.value, loadRoom };
}
